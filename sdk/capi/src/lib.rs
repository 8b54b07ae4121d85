//! The C ABI over the Rust core: what C, the C++ headers and other
//! languages link (`libfbksd.so`, `libfbksd.a`). Three sides:
//! - techniques: [`client`] (over [`fbksd_client`]), with [`layout`] and
//!   [`scene_info`];
//! - renderers: [`renderer`] (over [`fbksd_renderer`]): a server run from
//!   callbacks, and sample pipes that any thread may open;
//! - image quality metrics: [`iqa`] (over [`fbksd_iqa`]): the command line
//!   of a metric program, its input images, and its report.
//!
//! Conventions, for every function:
//! - It returns an [`FbksdStatus`]; on failure, [`fbksd_last_error`] gives
//!   a message for this thread, valid until the thread's next call.
//! - No panic crosses the boundary: a panic becomes [`FbksdStatus::Panic`]
//!   with its message.
//! - Handles are opaque; each `*_new` has its `*_free`; null handles are
//!   refused with [`FbksdStatus::InvalidArgument`].
//!
//! The header `include/fbksd/fbksd.h` is generated from this file by
//! cbindgen and committed; a test fails when it is stale (rerun it with
//! `FBKSD_REGENERATE_HEADER=1` to refresh it).
#![deny(missing_docs)]
// Every exported function checks its pointers itself; the C caller cannot mark them unsafe.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

pub mod client;
pub mod iqa;
pub mod layout;
pub mod renderer;
pub mod scene_info;

use std::cell::RefCell;
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// The outcome of a call.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FbksdStatus {
    /// Success.
    Ok = 0,
    /// A null pointer, bad UTF-8, or a value out of range.
    InvalidArgument = 1,
    /// Not started by a manager (and not in debug mode), or the connection failed.
    Connection = 2,
    /// The sample layout is invalid.
    Layout = 3,
    /// The manager refused a request (budget, order of calls, …); the run is over.
    Refused = 4,
    /// A scene-info key is missing or has another type.
    SceneInfo = 5,
    /// A call out of order (e.g. samples before a layout, or after the result).
    Usage = 6,
    /// Anything else (protocol, shared memory).
    Failed = 7,
    /// A bug: the library panicked (the message says where).
    Panic = 8,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

pub(crate) fn set_error(message: &str) {
    let c = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

/// The message of the last failed call on this thread ("" if none).
#[no_mangle]
pub extern "C" fn fbksd_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}

/// Runs `f`, turning errors and panics into a status and a message.
pub(crate) fn guard(f: impl FnOnce() -> Result<(), (FbksdStatus, String)>) -> FbksdStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => FbksdStatus::Ok,
        Ok(Err((status, message))) => {
            set_error(&message);
            status
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            set_error(&format!("internal error (panic): {what}"));
            FbksdStatus::Panic
        }
    }
}

pub(crate) fn client_error(e: fbksd_client::ClientError) -> (FbksdStatus, String) {
    use fbksd_client::ClientError as E;
    let status = match &e {
        E::NoRendezvous | E::Debug(_) | E::Connection(_) | E::Closed => FbksdStatus::Connection,
        E::Layout(_) => FbksdStatus::Layout,
        E::Refused { .. } => FbksdStatus::Refused,
        E::SceneInfo(_) => FbksdStatus::SceneInfo,
        E::Usage(_) => FbksdStatus::Usage,
        _ => FbksdStatus::Failed,
    };
    (status, e.to_string())
}

pub(crate) fn invalid(what: &str) -> (FbksdStatus, String) {
    (FbksdStatus::InvalidArgument, what.to_string())
}

/// A C string argument as `&str`.
pub(crate) fn text<'a>(p: *const c_char, what: &str) -> Result<&'a str, (FbksdStatus, String)> {
    if p.is_null() {
        return Err(invalid(&format!("{what} is null")));
    }
    // SAFETY: the caller passes a NUL-terminated string that outlives the call.
    unsafe { CStr::from_ptr(p) }.to_str().map_err(|_| invalid(&format!("{what} is not UTF-8")))
}

/// Turns a handle pointer into a reference, refusing null.
pub(crate) fn handle<'a, T>(p: *mut T, what: &str) -> Result<&'a mut T, (FbksdStatus, String)> {
    // SAFETY: a non-null handle comes from this library and is used by one thread at a time.
    unsafe { p.as_mut() }.ok_or_else(|| invalid(&format!("{what} is null")))
}

/// Sets this thread's last-error message, for callbacks (a renderer's or
/// a technique's) that report a failure with a status: the library passes
/// the message on with it.
#[no_mangle]
pub extern "C" fn fbksd_set_last_error(message: *const c_char) {
    let text = if message.is_null() {
        String::new()
    } else {
        // SAFETY: the caller passes a NUL-terminated string.
        unsafe { CStr::from_ptr(message) }.to_string_lossy().into_owned()
    };
    set_error(&text);
}

/// This thread's last-error message as a Rust string.
pub(crate) fn last_error() -> String {
    LAST_ERROR.with(|e| e.borrow().to_string_lossy().into_owned())
}

/// Frees a handle made by `Box::into_raw` (null is ignored).
pub(crate) fn free_handle<T>(p: *mut T) {
    if !p.is_null() {
        // SAFETY: the handle came from this library's *_new and is freed once.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(p) })));
    }
}
