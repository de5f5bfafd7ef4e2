//! Why wgpu found no hardware GPU, in one line: what the Vulkan loader and its drivers say.
//!
//! wgpu reports only the adapters it found. On a machine with the NVIDIA driver but without the
//! Vulkan loader (`libvulkan1`) or the GL vendor-neutral libraries the driver's Vulkan ICD links
//! (`libglvnd0`, `libegl1`), it finds none and says nothing more. Here the loader is opened as
//! wgpu would open it, each driver manifest (ICD JSON) the loader would read is listed, and each
//! driver library is opened to catch the error the loader hides (a missing `libGLdispatch.so.0`,
//! say). Only called when no hardware adapter was found.

use std::path::{Path, PathBuf};

/// The packages that usually make a present GPU visible to Vulkan (Debian/Ubuntu names).
pub const FIX_PACKAGES: &str = "libvulkan1, libglvnd0, libegl1";

/// What the Vulkan loader and its drivers say: one line (the loader's state, every driver manifest
/// and whether its library loads, the packages that usually fix it and the next step,
/// `VK_LOADER_DEBUG=error`), and whether anything in it failed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Diagnosis {
    /// The line.
    pub line: String,
    /// The loader does not load, no driver manifest was found, or a driver's library (or one it
    /// needs) does not load: a GPU may be there and unseen. False on a machine whose drivers all
    /// load and simply drive no GPU (a VM with Mesa's drivers): there the line is noise.
    pub failed: bool,
}

/// [`diagnosis_with`] for the manifests of `VK_DRIVER_FILES` / `VK_ICD_FILENAMES` when set, else
/// the loader's standard folders.
pub fn diagnosis() -> Diagnosis {
    let from_env = std::env::var("VK_DRIVER_FILES").ok().filter(|v| !v.is_empty()).or_else(|| std::env::var("VK_ICD_FILENAMES").ok().filter(|v| !v.is_empty()));
    diagnosis_with(from_env.as_deref())
}

/// [`Diagnosis::line`] of [`diagnosis_with`].
pub fn diagnose_with(driver_files: Option<&str>) -> String {
    diagnosis_with(driver_files).line
}

/// The [`Diagnosis`] for the manifests of `driver_files` (a `:`-separated list of JSON files or
/// folders, as `VK_DRIVER_FILES`), or the standard folders for None.
pub fn diagnosis_with(driver_files: Option<&str>) -> Diagnosis {
    let (loader, loader_ok) = match open_library("libvulkan.so.1") {
        Ok(()) => ("Vulkan: the loader libvulkan.so.1 loads".to_string(), true),
        Err(e) => (format!("Vulkan: the loader libvulkan.so.1 does not load ({e})"), false),
    };
    let manifests = match driver_files {
        Some(list) => manifests_in(list.split(':').filter(|s| !s.is_empty()).map(PathBuf::from).collect()),
        None => manifests_in(standard_manifest_folders()),
    };
    let (drivers, drivers_ok) = if manifests.is_empty() {
        let line = match driver_files {
            Some(list) => format!("no driver manifest (ICD JSON) in {list}"),
            None => "no driver manifest (ICD JSON) in /usr/share/vulkan/icd.d, /etc/vulkan/icd.d or /usr/local/share/vulkan/icd.d".to_string(),
        };
        (line, false)
    } else {
        let each: Vec<(String, bool)> = manifests.iter().map(|m| describe_manifest(m)).collect();
        let all_load = each.iter().all(|(_, ok)| *ok);
        (format!("driver manifests: {}", each.into_iter().map(|(d, _)| d).collect::<Vec<_>>().join("; ")), all_load)
    };
    let line = format!(
        "{loader}; {drivers}. Packages that usually fix this: {FIX_PACKAGES} (apt-get install -y {}); next, run with VK_LOADER_DEBUG=error to see what the loader rejects",
        FIX_PACKAGES.replace(", ", " ")
    );
    Diagnosis { line, failed: !(loader_ok && drivers_ok) }
}

/// The loader's standard manifest folders (Linux).
fn standard_manifest_folders() -> Vec<PathBuf> {
    let mut dirs = vec![PathBuf::from("/etc/vulkan/icd.d"), PathBuf::from("/usr/local/etc/vulkan/icd.d")];
    let data = std::env::var("XDG_DATA_DIRS").unwrap_or_default();
    for d in data.split(':').filter(|s| !s.is_empty()) {
        dirs.push(Path::new(d).join("vulkan/icd.d"));
    }
    for d in ["/usr/local/share/vulkan/icd.d", "/usr/share/vulkan/icd.d"] {
        let p = PathBuf::from(d);
        if !dirs.contains(&p) {
            dirs.push(p);
        }
    }
    dirs
}

/// The JSON manifests among `paths` (files as given, folders listed, sorted).
fn manifests_in(paths: Vec<PathBuf>) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(&p)
                .map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).filter(|f| f.extension().is_some_and(|x| x == "json")).collect())
                .unwrap_or_default();
            found.sort();
            out.extend(found);
        } else if p.extension().is_some_and(|x| x == "json") {
            out.push(p);
        }
    }
    out
}

/// "name.json → library: loads" or why not, and whether it loads.
fn describe_manifest(manifest: &Path) -> (String, bool) {
    let name = manifest.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| manifest.display().to_string());
    let text = match std::fs::read_to_string(manifest) {
        Ok(t) => t,
        Err(e) => return (format!("{name}: cannot be read ({e})"), false),
    };
    let library = serde_json::from_str::<serde_json::Value>(&text)
        .ok()
        .and_then(|v| v.get("ICD").and_then(|icd| icd.get("library_path")).and_then(|p| p.as_str().map(str::to_string)));
    let Some(library) = library else {
        return (format!("{name}: no ICD.library_path"), false);
    };
    // a relative path with a slash is relative to the manifest; a bare name goes through the linker's search
    let path = if library.contains('/') && !library.starts_with('/') {
        manifest.parent().unwrap_or(Path::new(".")).join(&library).display().to_string()
    } else {
        library.clone()
    };
    match open_library(&path) {
        Ok(()) => (format!("{name} → {library}: loads"), true),
        Err(e) => (format!("{name} → {library}: does not load ({e})"), false),
    }
}

/// Opens and closes a shared library as the Vulkan loader would (`dlopen`, `RTLD_NOW`): Ok, or the
/// linker's error (the library or one it needs is missing).
#[cfg(target_os = "linux")]
fn open_library(path: &str) -> Result<(), String> {
    let c = std::ffi::CString::new(path).map_err(|_| "a path with a NUL byte".to_string())?;
    // SAFETY: dlopen with a valid C string; the handle is closed at once; dlerror's string is
    // copied before any other dl call
    unsafe {
        let handle = libc::dlopen(c.as_ptr(), libc::RTLD_NOW | libc::RTLD_LOCAL);
        if handle.is_null() {
            let err = libc::dlerror();
            return Err(if err.is_null() { "unknown error".into() } else { std::ffi::CStr::from_ptr(err).to_string_lossy().into_owned() });
        }
        libc::dlclose(handle);
    }
    Ok(())
}

/// Elsewhere the libraries are not probed.
#[cfg(not(target_os = "linux"))]
fn open_library(_path: &str) -> Result<(), String> {
    Err("not probed on this system".into())
}
