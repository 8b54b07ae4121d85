//! `fbksd._native.RenderingServer`: the renderer side of the protocol in
//! Python (the counterpart of the original C++ `RenderingServer` and
//! `SamplesPipe`), over the Rust renderer API ([`fbksd_renderer`]).
//!
//! The Python renderer gives three callables: the scene info (a dict), the
//! layout check (it may refuse features it cannot compute), and `fill`,
//! called once per tile with the tile's sample positions and a numpy view of
//! its samples in the shared memory, zero-copy. The positions are drawn
//! here, with the SDK's stratified sampler, exactly as the built-in
//! renderers draw them: OUTPUT random parameters are written into the
//! samples, INPUT ones are read from them.

use fbksd_core::layout::{Element, ElementIo};
use fbksd_core::scene_info::SceneValue;
use fbksd_core::Tile;
use fbksd_renderer::sampler::{Dimensions, Sampler, Strata};
use fbksd_renderer::{Evaluation, MappingGuard, RenderingServer};
use numpy::ndarray::ArrayView2;
use numpy::{PyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyTypeError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

type BoxError = Box<dyn std::error::Error + Send + Sync>;

/// Keeps the renderer's shared memory mapped while arrays view it.
#[pyclass(frozen, module = "fbksd._native", name = "_RendererMapping")]
struct RendererMapping(#[allow(dead_code)] MappingGuard);

/// A renderer's connection to the manager: see the module documentation
/// of `fbksd.renderer`.
#[pyclass(module = "fbksd.renderer", name = "RenderingServer", unsendable)]
pub struct PyRenderingServer {
    scene_info: Py<PyAny>,
    set_layout: Option<Py<PyAny>>,
    fill: Py<PyAny>,
    tile_size: u32,
}

/// A Python exception as an error the manager reports, with its traceback.
fn boxed(py: Python<'_>, e: PyErr) -> BoxError {
    let trace = e.traceback(py).and_then(|t| t.format().ok()).unwrap_or_default();
    format!("{trace}{e}").into()
}

/// Scene info from a dict of int, float, bool and str values.
fn scene_info(dict: &Bound<'_, PyAny>) -> PyResult<fbksd_core::SceneInfo> {
    let dict = dict.cast::<PyDict>().map_err(|_| PyTypeError::new_err("scene_info() must return a dict"))?;
    let mut info = fbksd_core::SceneInfo::new();
    for (k, v) in dict.iter() {
        let key: String = k.extract()?;
        let value = if let Ok(b) = v.extract::<bool>() {
            SceneValue::Bool(b)
        } else if let Ok(i) = v.extract::<i64>() {
            SceneValue::Int(i)
        } else if let Ok(x) = v.extract::<f64>() {
            SceneValue::Float(x)
        } else if let Ok(s) = v.extract::<String>() {
            SceneValue::String(s)
        } else {
            return Err(PyTypeError::new_err(format!("scene info {key:?}: expected int, float, bool or str, got {v}")));
        };
        info.set(&key, value);
    }
    Ok(info)
}

/// Draws the positions of a tile's samples (rows of 7 random parameters),
/// writing OUTPUT parameters into the samples and taking INPUT ones from
/// them, and each sample's key ([`Dimensions::key`]) for the renderer's own
/// random numbers.
fn positions(
    eval: &Evaluation,
    sampler: &Sampler,
    tile: Tile,
    first: u64,
    samples: &mut [f32],
) -> (Vec<[f64; 7]>, Vec<u64>) {
    let layout = eval.layout();
    let size = layout.sample_size();
    let inputs = layout.input_offsets();
    let outputs: Vec<(usize, usize)> = layout
        .elements()
        .iter()
        .enumerate()
        .filter_map(|(offset, (e, io))| match (e, io) {
            (Element::Parameter(p), ElementIo::Output) => Some((p.index(), offset)),
            _ => None,
        })
        .collect();
    let mut drawn = Vec::with_capacity(tile.sample_count() as usize);
    let mut keys = Vec::with_capacity(tile.sample_count() as usize);
    match tile {
        Tile::Pixels { rect, spp } => {
            let strata = Strata::new(spp as u64);
            for y in rect.y0..rect.y1 {
                for x in rect.x0..rect.x1 {
                    let pixel = sampler.pixel(x, y);
                    for s in 0..spp as u64 {
                        drawn.push(sampler.pixel_sample(&pixel, &strata, s, 0x7F));
                        keys.push(Dimensions::of_pixel_sample(&pixel, s).key());
                    }
                }
            }
        }
        Tile::Samples { count } => {
            drawn.extend((first..first + count).map(|i| sampler.free_sample(i)));
            keys.extend((first..first + count).map(|i| Dimensions::of_free_sample(sampler, i).key()));
        }
    }
    for (p, sample) in drawn.iter_mut().zip(samples.chunks_exact_mut(size)) {
        for (d, input) in inputs.iter().enumerate() {
            if let Some(i) = input {
                p[d] = sample[*i] as f64;
            }
        }
        for &(d, offset) in &outputs {
            sample[offset] = p[d] as f32;
        }
    }
    (drawn, keys)
}

fn evaluate(eval: &Evaluation, fill: &Py<PyAny>) -> Result<(), BoxError> {
    let sampler = Sampler::new(eval.width(), eval.height(), eval.request);
    let size = eval.layout().sample_size();
    let guard = eval.mapping();
    for (tile, first) in eval.plan_with_free_starts() {
        let mut pipe = eval.pipe(tile)?;
        let n = pipe.len() as usize;
        let (drawn, keys) = positions(eval, &sampler, tile, first, pipe.raw());
        let data = pipe.raw().as_mut_ptr();
        Python::attach(|py| -> PyResult<()> {
            let keep = Bound::new(py, RendererMapping(guard.clone()))?;
            // One flat buffer for the (n, 7) array, not a vector per row.
            let flat: Vec<f64> = drawn.into_iter().flatten().collect();
            let positions = numpy::ndarray::Array2::from_shape_vec((n, 7), flat)
                .map(|a| PyArray2::from_owned_array(py, a))
                .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
            // SAFETY: the pipe's n·size floats, in shared memory that `keep` keeps mapped;
            // this thread alone writes them until the pipe is finished.
            let view = unsafe { ArrayView2::from_shape_ptr((n, size), data as *const f32) };
            let samples = unsafe { PyArray2::borrow_from_array(&view, keep.into_any()) };
            // The view was made from a read-only borrow; the renderer writes through it.
            unsafe { (*samples.as_array_ptr()).fields.flags |= numpy::npyffi::NPY_ARRAY_WRITEABLE };
            let info = PyDict::new(py);
            match tile {
                Tile::Pixels { rect, spp } => {
                    info.set_item("x0", rect.x0)?;
                    info.set_item("y0", rect.y0)?;
                    info.set_item("x1", rect.x1)?;
                    info.set_item("y1", rect.y1)?;
                    info.set_item("spp", spp)?;
                }
                Tile::Samples { count } => {
                    info.set_item("count", count)?;
                    info.set_item("first", first)?;
                }
            }
            info.set_item("keys", numpy::PyArray1::from_vec(py, keys))?;
            fill.call1(py, (info, positions, samples))?;
            Ok(())
        })
        .map_err(|e| Python::attach(|py| boxed(py, e)))?;
        pipe.finish()?;
    }
    Ok(())
}

#[pymethods]
impl PyRenderingServer {
    #[new]
    #[pyo3(signature = (scene_info, fill, set_layout=None, tile_size=32))]
    fn new(scene_info: Py<PyAny>, fill: Py<PyAny>, set_layout: Option<Py<PyAny>>, tile_size: u32) -> Self {
        PyRenderingServer { scene_info, set_layout, fill, tile_size }
    }

    /// Serves the manager until it ends the session (started by `fbksd run`).
    fn run(&self, py: Python<'_>) -> PyResult<()> {
        let info = Python::attach(|py| self.scene_info.call0(py).and_then(|v| scene_info(v.bind(py))))?;
        let set_layout = self.set_layout.as_ref().map(|f| f.clone_ref(py));
        let fill = self.fill.clone_ref(py);
        let tile_size = self.tile_size;
        let server = RenderingServer::new()
            .on_get_tile_size(move || tile_size)
            .on_get_scene_info(move || info.clone())
            .on_set_parameters(move |layout| {
                let Some(f) = &set_layout else { return Ok(()) };
                Python::attach(|py| {
                    let elements = PyList::empty(py);
                    for (offset, (e, io)) in layout.elements().iter().enumerate() {
                        let (name, number) = match e {
                            Element::Parameter(p) => (p.name(), 0),
                            Element::Feature(f, n) => (f.name(), *n),
                        };
                        let io = if *io == ElementIo::Input { "INPUT" } else { "OUTPUT" };
                        elements.append((name, number, offset, io))?;
                    }
                    f.call1(py, (elements,)).map(|_| ())
                })
                .map_err(|e| Python::attach(|py| boxed(py, e)))
            })
            .on_evaluate_samples(move |eval| evaluate(eval, &fill));
        // The server runs here, on this thread, without the GIL, so that the
        // evaluate thread can take it; its callbacks take it when they need it.
        struct SameThread(RenderingServer);
        // SAFETY: `detach` runs the closure on the calling thread; nothing crosses threads.
        unsafe impl Send for SameThread {}
        impl SameThread {
            fn run(self) -> Result<(), fbksd_renderer::RendererError> {
                self.0.run()
            }
        }
        let server = SameThread(server);
        py.detach(move || server.run()).map_err(|e| PyRuntimeError::new_err(e.to_string()))
    }
}

/// A scene's digest ([`fbksd_exchange::scenes::scene_digest`]): what a
/// Python renderer's reference note records, by the rule every renderer shares.
#[pyfunction]
fn scene_digest(scene_file: std::path::PathBuf) -> PyResult<String> {
    fbksd_exchange::scenes::scene_digest(&scene_file)
        .map_err(|e| pyo3::exceptions::PyOSError::new_err(format!("{}: {e}", scene_file.display())))
}

/// A reference's key ([`fbksd_exchange::scenes::reference_key`]), which a
/// renderer prints for `reference --key`.
#[pyfunction]
fn reference_key(generator: &str, samples_per_pixel: u64, scene_digest: &str) -> String {
    fbksd_exchange::scenes::reference_key(generator, samples_per_pixel, scene_digest)
}

/// The key of the reference a note (`reference.json`) describes
/// ([`fbksd_exchange::scenes::note_reference_key`]): a reference is current
/// when it equals the key the renderer would make now.
#[pyfunction]
fn note_reference_key(note: &[u8]) -> PyResult<String> {
    fbksd_exchange::scenes::note_reference_key(note).map_err(pyo3::exceptions::PyValueError::new_err)
}

/// A scene directory's metadata (or the `fbksd-scene.json` itself), read
/// and checked as the Rust renderers read it ([`SceneMeta::load`]) and
/// checked to be `renderer`'s ([`SceneMeta::expect_renderer`]), with the
/// paths a reference command needs resolved against the directory. A bad
/// file raises `ValueError` naming the file and what is wrong.
#[pyfunction]
fn scene_meta<'py>(py: Python<'py>, path: std::path::PathBuf, renderer: &str) -> PyResult<Bound<'py, PyDict>> {
    use fbksd_exchange::scenes::{ReferenceMethod, SceneMeta, FEATURE_BUFFERS};
    let bad = |message: String| pyo3::exceptions::PyValueError::new_err(message);
    let meta = SceneMeta::load(&path).map_err(|e| bad(e.to_string()))?;
    meta.expect_renderer(renderer).map_err(bad)?;
    let dict = PyDict::new(py);
    dict.set_item("name", &meta.name)?;
    dict.set_item("dir", &meta.dir)?;
    dict.set_item("width", meta.width)?;
    dict.set_item("height", meta.height)?;
    dict.set_item("scene_file", meta.scene_file())?;
    dict.set_item("reference_file", meta.reference_file())?;
    dict.set_item("note_file", meta.reference_note_file())?;
    // None for a closed-form reference, which no renderer renders.
    let spp = match meta.reference {
        ReferenceMethod::Render { spp } => Some(spp),
        ReferenceMethod::ClosedForm { .. } => None,
    };
    dict.set_item("reference_spp", spp)?;
    let buffers = PyDict::new(py);
    for name in FEATURE_BUFFERS {
        buffers.set_item(name, meta.feature_buffer_file(name))?;
    }
    dict.set_item("feature_buffers", buffers)?;
    Ok(dict)
}

/// Adds the renderer side to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyRenderingServer>()?;
    m.add_function(wrap_pyfunction!(scene_digest, m)?)?;
    m.add_function(wrap_pyfunction!(reference_key, m)?)?;
    m.add_function(wrap_pyfunction!(note_reference_key, m)?)?;
    m.add_function(wrap_pyfunction!(scene_meta, m)?)?;
    m.add("FEATURE_BUFFERS", fbksd_exchange::scenes::FEATURE_BUFFERS.to_vec())?;
    m.add("FEATURE_BUFFER_SPP", fbksd_exchange::scenes::FEATURE_BUFFER_SPP)?;
    Ok(())
}
