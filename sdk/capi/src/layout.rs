//! Sample layouts: built by techniques, read by renderers.

use crate::{free_handle, guard, handle, invalid, text, FbksdStatus};
use fbksd_client::{ElementIo, SampleLayout};
use std::ffi::{c_char, CString};

/// A sample layout: under construction (techniques) or as set by the
/// technique (renderers) (opaque).
#[derive(Default)]
pub struct FbksdLayout {
    layout: SampleLayout,
    /// The element names as C strings, in step with `layout.entries`.
    names: Vec<CString>,
}

impl FbksdLayout {
    /// The layout as the technique wrote it.
    pub(crate) fn source(&self) -> &SampleLayout {
        &self.layout
    }

    /// The C view of a layout.
    pub(crate) fn of(layout: &SampleLayout) -> FbksdLayout {
        let names = layout.entries.iter().map(|e| CString::new(e.name.clone()).unwrap_or_default()).collect();
        FbksdLayout { layout: layout.clone(), names }
    }
}

/// One element of a layout, as [`fbksd_layout_element`] reports it.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct FbksdElement {
    /// The name (e.g. "COLOR_R"), valid as long as the layout.
    pub name: *const c_char,
    /// Intersection number of a numbered feature (0 or 1), else 0.
    pub number: u32,
    /// Whether the technique writes it (INPUT random parameters).
    pub input: bool,
}

/// A new, empty layout (roughness threshold 0.1). Free it with [`fbksd_layout_free`].
#[no_mangle]
pub extern "C" fn fbksd_layout_new() -> *mut FbksdLayout {
    Box::into_raw(Box::new(FbksdLayout::default()))
}

/// Frees a layout (null is ignored).
#[no_mangle]
pub extern "C" fn fbksd_layout_free(layout: *mut FbksdLayout) {
    free_handle(layout)
}

/// Appends element `name` (e.g. "COLOR_R", "IMAGE_X"); `input` marks a
/// random parameter the technique gives; `number` picks the intersection
/// of a numbered feature (0 or 1). Checked when the layout is set.
#[no_mangle]
pub extern "C" fn fbksd_layout_add(
    layout: *mut FbksdLayout,
    name: *const c_char,
    input: bool,
    number: u32,
) -> FbksdStatus {
    guard(|| {
        let l = handle(layout, "layout")?;
        let name = text(name, "name")?;
        if number > 0 && input {
            return Err(invalid("only random parameters can be INPUT, and they are not numbered"));
        }
        let io = if input { ElementIo::Input } else { ElementIo::Output };
        let current = std::mem::take(&mut l.layout);
        l.layout = if number > 0 { current.with_number(name, number) } else { current.with_io(name, io) };
        l.names.push(CString::new(name).map_err(|_| invalid("name holds a NUL byte"))?);
        Ok(())
    })
}

/// Sets the Beckmann roughness threshold of the DIFFUSE_COLOR features.
#[no_mangle]
pub extern "C" fn fbksd_layout_set_roughness_threshold(layout: *mut FbksdLayout, threshold: f32) -> FbksdStatus {
    guard(|| {
        let l = handle(layout, "layout")?;
        let current = std::mem::take(&mut l.layout);
        l.layout = current.with_roughness_threshold(threshold);
        Ok(())
    })
}

/// Number of elements (0 for null).
#[no_mangle]
pub extern "C" fn fbksd_layout_len(layout: *const FbksdLayout) -> usize {
    // SAFETY: a non-null handle comes from this library.
    unsafe { layout.as_ref() }.map_or(0, |l| l.layout.entries.len())
}

/// Element `index` (0-based, in memory order) into `*out`.
#[no_mangle]
pub extern "C" fn fbksd_layout_element(
    layout: *const FbksdLayout,
    index: usize,
    out: *mut FbksdElement,
) -> FbksdStatus {
    guard(|| {
        // SAFETY: a non-null handle comes from this library.
        let l = unsafe { layout.as_ref() }.ok_or_else(|| invalid("layout is null"))?;
        let entry = l.layout.entries.get(index).ok_or_else(|| {
            invalid(&format!("element {index} is out of range (the layout has {})", l.layout.entries.len()))
        })?;
        *handle(out, "out")? =
            FbksdElement { name: l.names[index].as_ptr(), number: entry.number, input: entry.io == ElementIo::Input };
        Ok(())
    })
}

/// The Beckmann roughness threshold of the DIFFUSE_COLOR features (0.1 unless set; 0 for null).
#[no_mangle]
pub extern "C" fn fbksd_layout_roughness_threshold(layout: *const FbksdLayout) -> f32 {
    // SAFETY: a non-null handle comes from this library.
    unsafe { layout.as_ref() }.map_or(0.0, |l| l.layout.roughness_threshold)
}
