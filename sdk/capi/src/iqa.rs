//! The image-quality-metric side: a metric is a program (thesis A.3) run as
//! `<exe> [--value-file F] [--map-file M.png] <reference.exr> <test.exr>`.
//! [`fbksd_iqa_new`] parses that command line, answers `--help` and
//! `--info` itself, and loads both images (full 32-bit float); the metric
//! computes its value and calls [`fbksd_iqa_report`], which prints
//! `{"<acronym>": value}` (or writes the value file) and writes the error
//! map in the same colour map as the built-in metrics.

use crate::{free_handle, guard, handle, invalid, text, FbksdStatus};
use fbksd_iqa::image::Image;
use fbksd_iqa::{ErrorMap, MapScale};
use std::ffi::{c_char, c_int};
use std::path::{Path, PathBuf};

/// A metric program's state: its description, options and input images (opaque).
pub struct FbksdIqa {
    acronym: String,
    value_file: Option<PathBuf>,
    map_file: Option<PathBuf>,
    has_error_map: bool,
    reference: Image,
    test: Image,
}

/// Which input image.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FbksdIqaImage {
    /// The reference image.
    Reference = 0,
    /// The image under test.
    Test = 1,
}

fn usage(exe: &str) -> String {
    format!(
        "usage: {exe} [options] <ref-img-path> <test-img-path>\n\
         \n\
         Prints the metric's value as {{\"<acronym>\": value}} on stdout.\n\
         \n\
         options:\n  \
           -h, --help                 this message\n  \
           --info                     the metric's description (IQA info.json) and exit\n  \
           --value-file <path>        write the value there instead of stdout\n  \
           --map-file <path.png>      write the error map (metrics that have one)\n"
    )
}

/// Parses the metric's command line and loads its two images. `--help` and
/// `--info` print and exit the process with status 0, as in the original.
/// A wrong command line, a missing image or images of different sizes are
/// errors whose message says which.
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub extern "C" fn fbksd_iqa_new(
    argc: c_int,
    argv: *const *const c_char,
    acronym: *const c_char,
    full_name: *const c_char,
    reference: *const c_char,
    lower_is_better: bool,
    has_error_map: bool,
    out: *mut *mut FbksdIqa,
) -> FbksdStatus {
    guard(|| {
        let out = handle(out, "out")?;
        let acronym = text(acronym, "acronym")?.to_string();
        if acronym.is_empty() {
            return Err(invalid("the acronym is empty"));
        }
        let full_name = text(full_name, "full name")?.to_string();
        let citation = if reference.is_null() { String::new() } else { text(reference, "reference")?.to_string() };
        let mut args = Vec::new();
        for i in 0..argc.max(0) as usize {
            if argv.is_null() {
                return Err(invalid("argv is null"));
            }
            // SAFETY: argv holds argc valid pointers.
            args.push(text(unsafe { *argv.add(i) }, "an argv entry")?.to_string());
        }
        let exe = args.first().cloned().unwrap_or_else(|| acronym.clone());
        let usage_error = |m: String| (FbksdStatus::Usage, format!("{m}\n{}", usage(&exe)));

        let (mut value_file, mut map_file, mut paths) = (None, None, Vec::new());
        let mut rest = args.into_iter().skip(1);
        while let Some(arg) = rest.next() {
            match arg.as_str() {
                "-h" | "--help" => {
                    print!("{}", usage(&exe));
                    std::process::exit(0);
                }
                "--info" => {
                    let info = serde_json::json!({
                        "acronym": acronym, "name": full_name, "reference": citation,
                        "lower_is_better": lower_is_better, "has_error_map": has_error_map,
                        "executable": Path::new(&exe).file_name().map(|f| f.to_string_lossy()).unwrap_or_default(),
                    });
                    println!("{}", serde_json::to_string_pretty(&info).unwrap_or_default());
                    std::process::exit(0);
                }
                "--value-file" => {
                    value_file =
                        Some(PathBuf::from(rest.next().ok_or_else(|| usage_error("--value-file needs a path".into()))?))
                }
                "--map-file" => {
                    map_file =
                        Some(PathBuf::from(rest.next().ok_or_else(|| usage_error("--map-file needs a path".into()))?))
                }
                other if other.starts_with('-') => return Err(usage_error(format!("unknown option {other}"))),
                _ => paths.push(PathBuf::from(arg)),
            }
        }
        let [reference, test] = <[PathBuf; 2]>::try_from(paths)
            .map_err(|p| usage_error(format!("expected a reference and a test image, got {} paths", p.len())))?;
        let read = |p: &Path, what: &str| {
            Image::read(p).map_err(|e| (FbksdStatus::InvalidArgument, format!("{what} image {}: {e}", p.display())))
        };
        let (reference_image, test_image) = (read(&reference, "reference")?, read(&test, "test")?);
        if (reference_image.width, reference_image.height) != (test_image.width, test_image.height) {
            return Err(invalid(&format!(
                "the reference ({}×{}, {}) and the test image ({}×{}, {}) differ in size",
                reference_image.width,
                reference_image.height,
                reference.display(),
                test_image.width,
                test_image.height,
                test.display()
            )));
        }
        *out = Box::into_raw(Box::new(FbksdIqa {
            acronym,
            value_file,
            map_file,
            has_error_map,
            reference: reference_image,
            test: test_image,
        }));
        Ok(())
    })
}

/// Frees the metric's state (null is ignored).
#[no_mangle]
pub extern "C" fn fbksd_iqa_free(iqa: *mut FbksdIqa) {
    free_handle(iqa)
}

/// An input image: `*width × *height` RGB pixels, scanline order, owned by
/// `iqa` (null on error).
#[no_mangle]
pub extern "C" fn fbksd_iqa_image(
    iqa: *const FbksdIqa,
    which: FbksdIqaImage,
    width: *mut u32,
    height: *mut u32,
) -> *const f32 {
    let mut data = std::ptr::null();
    guard(|| {
        // SAFETY: a non-null handle comes from fbksd_iqa_new.
        let iqa = unsafe { iqa.as_ref() }.ok_or_else(|| invalid("iqa is null"))?;
        let image = match which {
            FbksdIqaImage::Reference => &iqa.reference,
            FbksdIqaImage::Test => &iqa.test,
        };
        *handle(width, "width")? = image.width;
        *handle(height, "height")? = image.height;
        data = image.rgb.as_ptr();
        Ok(())
    });
    data
}

/// Reports the metric's value, and its error map when `map` is not null:
/// `width × height` RGB values in [0, 1) (clamped; a pixel's error is the
/// mean of its three), written as a PNG if `--map-file` was given and the
/// metric declared an error map. A non-finite value is refused.
#[no_mangle]
pub extern "C" fn fbksd_iqa_report(
    iqa: *const FbksdIqa,
    value: f32,
    map: *const f32,
    width: u32,
    height: u32,
) -> FbksdStatus {
    guard(|| {
        // SAFETY: a non-null handle comes from fbksd_iqa_new.
        let iqa = unsafe { iqa.as_ref() }.ok_or_else(|| invalid("iqa is null"))?;
        if !value.is_finite() {
            return Err(invalid(&format!("the metric value is {value}: it must be a finite number")));
        }
        if let (Some(path), false, true) = (&iqa.map_file, map.is_null(), iqa.has_error_map) {
            if (width, height) != (iqa.reference.width, iqa.reference.height) {
                return Err(invalid(&format!(
                    "the error map is {width}×{height}, the images {}×{}",
                    iqa.reference.width, iqa.reference.height
                )));
            }
            // SAFETY: the caller passes width × height × 3 floats.
            let rgb = unsafe { std::slice::from_raw_parts(map, width as usize * height as usize * 3) };
            let values = rgb.chunks(3).map(|p| (p[0] + p[1] + p[2]) / 3.0).collect();
            ErrorMap { width, height, values, scale: MapScale::Linear { max: 1.0 } }
                .write_png(path)
                .map_err(|e| (FbksdStatus::Failed, format!("writing the error map {}: {e}", path.display())))?;
        }
        let json = serde_json::json!({ &iqa.acronym: value }).to_string();
        match &iqa.value_file {
            Some(path) => std::fs::write(path, format!("{json}\n"))
                .map_err(|e| (FbksdStatus::Failed, format!("writing the value file {}: {e}", path.display())))?,
            None => println!("{json}"),
        }
        Ok(())
    })
}
