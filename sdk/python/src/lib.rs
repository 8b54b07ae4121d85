//! `fbksd._native`: the Python technique API over the Rust client
//! ([`fbksd_client`]), re-exported by `fbksd.client`.
//!
//! Compatible with the original `fbksd.client` (thesis appendix B): the same
//! class and method names, tiles handed to callbacks as numpy arrays of shape
//! `(height, width, spp, sample_size)` that view the shared memory without
//! copying, and `SceneInfo.get` returning plain values. Added: adaptive
//! sampling (`evaluate_input_samples`), count requests
//! (`evaluate_sample_count`), INPUT elements in layouts, and errors as
//! `FbksdError` exceptions instead of aborts.
//!
//! Memory safety: every array that views shared memory holds a reference to
//! a `_Mapping` object that keeps that memory mapped, so an array kept
//! beyond its callback (or beyond `send_result`) reads stale data but never
//! crashes the interpreter.

mod renderer;

use fbksd_client::{BenchmarkClient as Client, ClientError, ElementIo, Mappings, SampleLayout, Spp};
use fbksd_core::scene_info::SceneValue;
use numpy::ndarray::{ArrayView2, ArrayView3, ArrayView4};
use numpy::{PyArray2, PyArray3, PyArray4};
use pyo3::exceptions::{PyKeyError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyList, PyTuple};
use pyo3::IntoPyObjectExt;
use std::sync::Mutex;

pyo3::create_exception!(
    fbksd,
    FbksdError,
    PyRuntimeError,
    "A failed FBKSD call: no manager to connect to, a refused request, an invalid layout, …"
);

fn error(e: ClientError) -> PyErr {
    FbksdError::new_err(e.to_string())
}

/// Keeps the client's shared memory mapped while arrays view it.
#[pyclass(frozen, module = "fbksd._native", name = "_Mapping")]
struct Mapping(#[allow(dead_code)] Mappings);

/// Information about the scene being rendered (`width`, `height`,
/// `max_spp`, `max_samples`, `has_dof`, …).
#[pyclass(frozen, module = "fbksd.client")]
struct SceneInfo(fbksd_core::SceneInfo);

#[pymethods]
impl SceneInfo {
    /// The value of `key` as a plain int, float, bool or str; KeyError if
    /// it does not exist.
    fn get(&self, py: Python<'_>, key: &str) -> PyResult<Py<PyAny>> {
        match self.0.value(key) {
            Some(SceneValue::Int(i)) => i.into_py_any(py),
            Some(SceneValue::Float(x)) => x.into_py_any(py),
            Some(SceneValue::Bool(b)) => b.into_py_any(py),
            Some(SceneValue::String(s)) => s.into_py_any(py),
            None => Err(PyKeyError::new_err(format!("scene info has no {key:?}"))),
        }
    }

    /// Whether `key` exists.
    fn has(&self, key: &str) -> bool {
        self.0.value(key).is_some()
    }

    fn __contains__(&self, key: &str) -> bool {
        self.has(key)
    }

    /// Every key, in a stable order.
    fn keys(&self) -> Vec<String> {
        self.0.iter().map(|(k, _)| k.to_string()).collect()
    }

    fn __repr__(&self) -> String {
        let items: Vec<String> = self.0.iter().map(|(k, v)| format!("{k}={v}")).collect();
        format!("SceneInfo({})", items.join(", "))
    }
}

/// The connection to the benchmark manager. Create one per process.
#[pyclass(frozen, module = "fbksd.client")]
struct BenchmarkClient {
    /// `None` once the result is sent; locked while a request runs, so a
    /// callback cannot start another request.
    client: Mutex<Option<Client>>,
    scene_info: fbksd_core::SceneInfo,
    width: usize,
    height: usize,
    /// The result buffer (mapped for as long as `mapping` lives).
    result: usize,
    /// Replaced once the layout is set, to cover the tile ring too.
    mapping: Mutex<Py<Mapping>>,
    /// Floats per sample, known without the client's lock (callbacks ask).
    sample_size: std::sync::atomic::AtomicUsize,
}

/// Runs one request: `run` gets the client and a slot for the first error a
/// callback raised; callbacks after a failure are skipped, the error is
/// raised once the request is over.
fn request(
    this: &BenchmarkClient,
    run: impl FnOnce(&mut Client, &mut Option<PyErr>) -> Result<(), ClientError>,
) -> PyResult<()> {
    let mut guard = this
        .client
        .try_lock()
        .map_err(|_| FbksdError::new_err("a request is in progress: callbacks cannot start another one"))?;
    let client = guard.as_mut().ok_or_else(|| FbksdError::new_err("the result was already sent"))?;
    let mut failure = None;
    let outcome = run(client, &mut failure);
    if let Some(e) = failure {
        return Err(e);
    }
    outcome.map_err(error)
}

/// Calls `f` unless an earlier callback failed; keeps the first error.
fn call(failure: &mut Option<PyErr>, f: impl FnOnce() -> PyResult<()>) {
    if failure.is_none() {
        if let Err(e) = f() {
            *failure = Some(e);
        }
    }
}

/// A numpy view of `(height, width, spp, sample_size)` floats at `data`.
fn tile_array<'py>(
    keep: &Bound<'py, Mapping>,
    shape: (usize, usize, usize, usize),
    data: *const f32,
) -> Bound<'py, PyArray4<f32>> {
    // SAFETY: `data` holds the tile's h·w·spp·size floats, contiguous in
    // this order, in shared memory that `keep` keeps mapped.
    let view = unsafe { ArrayView4::from_shape_ptr(shape, data) };
    unsafe { PyArray4::borrow_from_array(&view, keep.clone().into_any()) }
}

/// A numpy view of `count` samples of `size` floats at `data`.
fn samples_array<'py>(keep: &Bound<'py, Mapping>, data: &[f32], size: usize) -> Bound<'py, PyArray2<f32>> {
    let count = data.len().checked_div(size).unwrap_or(0);
    // SAFETY: as for tile_array.
    let view = unsafe { ArrayView2::from_shape_ptr((count, size), data.as_ptr()) };
    unsafe { PyArray2::borrow_from_array(&view, keep.clone().into_any()) }
}

/// A layout from the list form: `'COLOR_R'`, `('NORMAL_X', 1)` (a numbered
/// feature) or `('IMAGE_X', 'INPUT')`.
fn layout_of(elements: &Bound<'_, PyList>, roughness: f32) -> PyResult<SampleLayout> {
    let mut layout = SampleLayout::new().with_roughness_threshold(roughness);
    for (index, item) in elements.iter().enumerate() {
        let bad = || {
            PyTypeError::new_err(format!(
                "layout element {index}: expected a name, (name, number) or (name, 'INPUT'|'OUTPUT'), got {item}"
            ))
        };
        if let Ok(name) = item.extract::<String>() {
            layout = layout.with(&name);
            continue;
        }
        let pair = item.cast::<PyTuple>().map_err(|_| bad())?;
        if pair.len() != 2 {
            return Err(bad());
        }
        let name: String = pair.get_item(0)?.extract().map_err(|_| bad())?;
        let second = pair.get_item(1)?;
        if let Ok(number) = second.extract::<u32>() {
            layout = layout.with_number(&name, number);
        } else {
            let io = match second.extract::<String>().map_err(|_| bad())?.as_str() {
                "INPUT" => ElementIo::Input,
                "OUTPUT" => ElementIo::Output,
                other => {
                    return Err(PyValueError::new_err(format!(
                        "layout element {index} ({name}): direction must be 'INPUT' or 'OUTPUT', got {other:?}"
                    )))
                }
            };
            layout = layout.with_io(&name, io);
        }
    }
    Ok(layout)
}

impl BenchmarkClient {
    fn keep<'py>(&self, py: Python<'py>) -> Bound<'py, Mapping> {
        self.mapping.lock().unwrap().bind(py).clone()
    }
}

/// A pixel tile (read-only or writable: both have the same accessors) as
/// the callback arguments `(array, (x, y))`, the array viewing `$data`.
macro_rules! pixel_tile {
    ($keep:expr, $tile:expr, $data:expr) => {{
        let (w, h) = ($tile.end_x() - $tile.begin_x(), $tile.end_y() - $tile.begin_y());
        let shape = (h as usize, w as usize, $tile.spp() as usize, $tile.sample_size());
        let offset = ($tile.begin_x(), $tile.begin_y());
        (tile_array($keep, shape, $data), offset)
    }};
}

#[pymethods]
impl BenchmarkClient {
    /// Connects to the manager that started this process. With
    /// `--fbksd-renderer "<renderer> <scene>" --fbksd-spp N` among `argv`
    /// (default: `sys.argv`) it runs its own manager instead (debug mode).
    #[new]
    #[pyo3(signature = (argv = None))]
    fn new(py: Python<'_>, argv: Option<Vec<String>>) -> PyResult<Self> {
        let argv = match argv {
            Some(a) => a,
            None => py.import("sys")?.getattr("argv")?.extract()?,
        };
        let mut client = py.detach(|| Client::from_args(argv)).map_err(error)?;
        let scene_info = client.scene_info().clone();
        let (width, height) = (scene_info.width().unwrap_or(0) as usize, scene_info.height().unwrap_or(0) as usize);
        let result = client.result_buffer().as_mut_ptr() as usize;
        let mapping = Py::new(py, Mapping(client.mappings()))?;
        Ok(BenchmarkClient {
            client: Mutex::new(Some(client)),
            scene_info,
            width,
            height,
            result,
            mapping: Mutex::new(mapping),
            sample_size: Default::default(),
        })
    }

    /// Information about the scene.
    fn get_scene_info(&self) -> SceneInfo {
        SceneInfo(self.scene_info.clone())
    }

    /// Sets the sample layout (once): a list of names such as `'COLOR_R'`,
    /// `('NORMAL_X', 1)` for the second intersection, or `('IMAGE_X',
    /// 'INPUT')` for a parameter the technique writes; `roughness` is the
    /// Beckmann threshold of the DIFFUSE_COLOR features.
    #[pyo3(signature = (layout, roughness = 0.1))]
    fn set_sample_layout(slf: &Bound<'_, Self>, layout: &Bound<'_, PyList>, roughness: f32) -> PyResult<()> {
        let layout = layout_of(layout, roughness)?;
        let this = slf.get();
        request(this, |client, _| client.set_sample_layout(&layout))?;
        // The ring now exists: arrays made from here on keep it mapped too.
        let (mappings, size) = {
            let client = this.client.lock().unwrap();
            (client.as_ref().map(Client::mappings), client.as_ref().map_or(0, Client::sample_size))
        };
        this.sample_size.store(size, std::sync::atomic::Ordering::Relaxed);
        if let Some(m) = mappings {
            *this.mapping.lock().unwrap() = Py::new(slf.py(), Mapping(m))?;
        }
        Ok(())
    }

    /// Floats per sample of the layout (0 before one is set).
    fn sample_size(&self) -> usize {
        self.sample_size.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Samples left in the budget.
    fn remaining_samples(&self) -> PyResult<u64> {
        let guard = self.client.try_lock().map_err(|_| FbksdError::new_err("a request is in progress"))?;
        Ok(guard.as_ref().map_or(0, Client::remaining_samples))
    }

    /// The result image, `(height, width, 3)` float32, viewing the buffer
    /// `send_result` sends: write the final image into it.
    fn get_result_buffer<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f32>> {
        let keep = self.keep(py);
        // SAFETY: the result buffer holds height·width·3 floats and stays
        // mapped while `keep` lives.
        let view = unsafe { ArrayView3::from_shape_ptr((self.height, self.width, 3), self.result as *const f32) };
        unsafe { PyArray3::borrow_from_array(&view, keep.clone().into_any()) }
    }

    /// Requests `spp` samples per pixel. `consumer(tile, offset)` is called
    /// per tile: `tile` is `(height, width, spp, sample_size)` float32,
    /// `offset` the `(x, y)` of its upper-left pixel.
    fn evaluate_samples(slf: &Bound<'_, Self>, spp: u64, consumer: &Bound<'_, PyAny>) -> PyResult<()> {
        let keep = slf.get().keep(slf.py());
        request(slf.get(), |client, failure| {
            client.evaluate_samples(Spp(spp), |tile| {
                call(failure, || consumer.call1(pixel_tile!(&keep, tile, tile.data().as_ptr())).map(drop))
            })
        })
    }

    /// Requests `count` samples anywhere on the image (IMAGE_X/IMAGE_Y say
    /// where). `consumer(samples)` gets chunks of shape `(n, sample_size)`.
    fn evaluate_sample_count(slf: &Bound<'_, Self>, count: u64, consumer: &Bound<'_, PyAny>) -> PyResult<()> {
        let keep = slf.get().keep(slf.py());
        request(slf.get(), |client, failure| {
            let size = client.sample_size();
            client.evaluate_sample_count(count, |data| {
                call(failure, || consumer.call1((samples_array(&keep, data, size),)).map(drop))
            })
        })
    }

    /// Adaptive sampling: `producer(tile, offset)` writes the INPUT
    /// parameters of each tile (a writable array), then
    /// `consumer(tile, offset)` gets the rendered samples.
    fn evaluate_input_samples(
        slf: &Bound<'_, Self>,
        spp: u64,
        producer: &Bound<'_, PyAny>,
        consumer: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let keep = slf.get().keep(slf.py());
        request(slf.get(), |client, failure| {
            // Both callbacks need the failure slot; they never run at once.
            let failure = std::cell::RefCell::new(failure);
            client.evaluate_input_samples(
                Spp(spp),
                |tile| {
                    call(&mut failure.borrow_mut(), || {
                        let data = tile.data_mut().as_mut_ptr();
                        producer.call1(pixel_tile!(&keep, tile, data)).map(drop)
                    })
                },
                |tile| {
                    call(&mut failure.borrow_mut(), || {
                        consumer.call1(pixel_tile!(&keep, tile, tile.data().as_ptr())).map(drop)
                    })
                },
            )
        })
    }

    /// Count form of `evaluate_input_samples`: `producer(samples)` writes
    /// the INPUT parameters (IMAGE_X/IMAGE_Y included) of each chunk,
    /// `consumer(samples)` reads them back rendered.
    fn evaluate_input_sample_count(
        slf: &Bound<'_, Self>,
        count: u64,
        producer: &Bound<'_, PyAny>,
        consumer: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let keep = slf.get().keep(slf.py());
        request(slf.get(), |client, failure| {
            let size = client.sample_size();
            let failure = std::cell::RefCell::new(failure);
            client.evaluate_input_sample_count(
                count,
                |data| {
                    call(&mut failure.borrow_mut(), || producer.call1((samples_array(&keep, data, size),)).map(drop))
                },
                |data| {
                    call(&mut failure.borrow_mut(), || consumer.call1((samples_array(&keep, data, size),)).map(drop))
                },
            )
        })
    }

    /// Sends the result buffer; nothing more can be requested afterwards.
    fn send_result(&self, py: Python<'_>) -> PyResult<()> {
        let client = {
            let mut guard = self.client.try_lock().map_err(|_| FbksdError::new_err("a request is in progress"))?;
            guard.take().ok_or_else(|| FbksdError::new_err("the result was already sent"))?
        };
        py.detach(|| client.send_result()).map_err(error)
    }
}

/// The native module behind `fbksd.client`.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<BenchmarkClient>()?;
    m.add_class::<SceneInfo>()?;
    m.add("FbksdError", m.py().get_type::<FbksdError>())?;
    m.add("INPUT", "INPUT")?;
    m.add("OUTPUT", "OUTPUT")?;
    renderer::register(m)?;
    Ok(())
}
