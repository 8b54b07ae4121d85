//! Scene information: read by techniques (from their client), built by
//! renderers (in their scene-info callback).

use crate::{free_handle, guard, handle, invalid, text, FbksdStatus};
use fbksd_core::scene_info::{FromSceneValue, SceneValue};
use std::ffi::c_char;

/// Scene information: keys with integer, number, boolean or string values (opaque).
pub struct FbksdSceneInfo(pub(crate) fbksd_core::SceneInfo);

/// A new, empty scene info. Free it with [`fbksd_scene_info_free`].
#[no_mangle]
pub extern "C" fn fbksd_scene_info_new() -> *mut FbksdSceneInfo {
    Box::into_raw(Box::new(FbksdSceneInfo(fbksd_core::SceneInfo::new())))
}

/// A copy of `info` (null for null). Free it with [`fbksd_scene_info_free`].
#[no_mangle]
pub extern "C" fn fbksd_scene_info_clone(info: *const FbksdSceneInfo) -> *mut FbksdSceneInfo {
    // SAFETY: a non-null handle comes from this library.
    match unsafe { info.as_ref() } {
        Some(i) => Box::into_raw(Box::new(FbksdSceneInfo(i.0.clone()))),
        None => std::ptr::null_mut(),
    }
}

/// Replaces everything in `dst` by a copy of `src`.
#[no_mangle]
pub extern "C" fn fbksd_scene_info_copy(dst: *mut FbksdSceneInfo, src: *const FbksdSceneInfo) -> FbksdStatus {
    guard(|| {
        let copy = get(src)?.clone();
        handle(dst, "dst")?.0 = copy;
        Ok(())
    })
}

/// Adds every item of `src` to `dst`, replacing those with the same key
/// (`SceneInfo::merged` of the C++ API).
#[no_mangle]
pub extern "C" fn fbksd_scene_info_merge(dst: *mut FbksdSceneInfo, src: *const FbksdSceneInfo) -> FbksdStatus {
    guard(|| {
        let merged = get(dst)?.merged(get(src)?);
        handle(dst, "dst")?.0 = merged;
        Ok(())
    })
}

/// Frees a scene info made by [`fbksd_scene_info_new`] or
/// [`fbksd_scene_info_clone`] (null is ignored; never a client's).
#[no_mangle]
pub extern "C" fn fbksd_scene_info_free(info: *mut FbksdSceneInfo) {
    free_handle(info)
}

fn get<'a>(info: *const FbksdSceneInfo) -> Result<&'a fbksd_core::SceneInfo, (FbksdStatus, String)> {
    // SAFETY: a non-null handle comes from this library.
    unsafe { info.as_ref() }.map(|i| &i.0).ok_or_else(|| invalid("scene info is null"))
}

/// Looks up `key` as `T`.
fn value<T: FromSceneValue>(info: *const FbksdSceneInfo, key: *const c_char) -> Result<T, (FbksdStatus, String)> {
    let key = text(key, "key")?;
    get(info)?.get::<T>(key).map_err(|e| (FbksdStatus::SceneInfo, format!("scene info: {e}")))
}

/// Integer `key` (e.g. "width", "height", "max_spp").
#[no_mangle]
pub extern "C" fn fbksd_scene_info_int(info: *const FbksdSceneInfo, key: *const c_char, out: *mut i64) -> FbksdStatus {
    guard(|| {
        let v = value::<i64>(info, key)?;
        *handle(out, "out")? = v;
        Ok(())
    })
}

/// Number `key`.
#[no_mangle]
pub extern "C" fn fbksd_scene_info_float(
    info: *const FbksdSceneInfo,
    key: *const c_char,
    out: *mut f64,
) -> FbksdStatus {
    guard(|| {
        let v = value::<f64>(info, key)?;
        *handle(out, "out")? = v;
        Ok(())
    })
}

/// Boolean `key`.
#[no_mangle]
pub extern "C" fn fbksd_scene_info_bool(
    info: *const FbksdSceneInfo,
    key: *const c_char,
    out: *mut bool,
) -> FbksdStatus {
    guard(|| {
        let v = value::<bool>(info, key)?;
        *handle(out, "out")? = v;
        Ok(())
    })
}

/// String `key`, copied NUL-terminated into `buf` (`len` bytes).
/// `*needed` (if not null) receives the size the string needs, NUL
/// included; a too-small buffer is [`FbksdStatus::InvalidArgument`].
#[no_mangle]
pub extern "C" fn fbksd_scene_info_string(
    info: *const FbksdSceneInfo,
    key: *const c_char,
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
) -> FbksdStatus {
    guard(|| {
        let v = value::<String>(info, key)?;
        let bytes = v.as_bytes();
        if !needed.is_null() {
            // SAFETY: checked non-null; the caller's out parameter.
            unsafe { *needed = bytes.len() + 1 };
        }
        if buf.is_null() || len < bytes.len() + 1 {
            return Err(invalid(&format!("buffer of {len} bytes is too small for {} bytes", bytes.len() + 1)));
        }
        // SAFETY: buf holds len ≥ bytes.len() + 1 bytes.
        unsafe {
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), buf as *mut u8, bytes.len());
            *buf.add(bytes.len()) = 0;
        }
        Ok(())
    })
}

/// Whether `key` exists (false for a null info or key).
#[no_mangle]
pub extern "C" fn fbksd_scene_info_has(info: *const FbksdSceneInfo, key: *const c_char) -> bool {
    let mut has = false;
    guard(|| {
        has = get(info)?.value(text(key, "key")?).is_some();
        Ok(())
    });
    has
}

fn set(info: *mut FbksdSceneInfo, key: *const c_char, value: SceneValue) -> FbksdStatus {
    guard(|| {
        let key = text(key, "key")?.to_string();
        handle(info, "scene info")?.0.set(&key, value);
        Ok(())
    })
}

/// Sets integer `key`.
#[no_mangle]
pub extern "C" fn fbksd_scene_info_set_int(info: *mut FbksdSceneInfo, key: *const c_char, value: i64) -> FbksdStatus {
    set(info, key, SceneValue::Int(value))
}

/// Sets number `key`.
#[no_mangle]
pub extern "C" fn fbksd_scene_info_set_float(info: *mut FbksdSceneInfo, key: *const c_char, value: f64) -> FbksdStatus {
    set(info, key, SceneValue::Float(value))
}

/// Sets boolean `key`.
#[no_mangle]
pub extern "C" fn fbksd_scene_info_set_bool(info: *mut FbksdSceneInfo, key: *const c_char, value: bool) -> FbksdStatus {
    set(info, key, SceneValue::Bool(value))
}

/// Sets string `key` to the NUL-terminated UTF-8 `value`.
#[no_mangle]
pub extern "C" fn fbksd_scene_info_set_string(
    info: *mut FbksdSceneInfo,
    key: *const c_char,
    value: *const c_char,
) -> FbksdStatus {
    match text(value, "value") {
        Ok(v) => set(info, key, SceneValue::String(v.to_string())),
        Err((status, message)) => {
            crate::set_error(&message);
            status
        }
    }
}
