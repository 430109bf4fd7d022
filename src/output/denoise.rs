//! `--denoise`: Intel Open Image Denoise's `RT` filter on the beauty, guided by the albedo
//! and normal layers, written as an extra `denoised` layer beside every noisy one.
//!
//! As in Cycles and Karma the auxiliary layers are denoised first (prefiltered: their own
//! `RT` filter each) and the beauty's filter is told so (`cleanAux`), which keeps the noise
//! of the albedo and normal out of the result. The beauty is HDR (`hdr`).
//!
//! **Why the library is loaded at run time.** OIDN is a 50 MB C++ library that Debian does
//! not package; linking it (the `oidn` crate links at build time) would make every build
//! need it, and the README's build commands would fail on a fresh machine. lucerna instead
//! opens `libOpenImageDenoise` when `--denoise` asks for it, from (in order) `$LUCERNA_OIDN`
//! (the library or its folder), the `pyoidn` package of the Python environments lucerna
//! knows (`lucerna setup`'s, `$LUCERNA_PYTHON`'s, a development checkout's `.venv`), then
//! the system's library path. The ten functions it calls are OIDN 2's stable C API.

use crate::error::{Error, Result};
use libloading::{Library, Symbol};
use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::path::{Path, PathBuf};

type Device = *mut c_void;
type Filter = *mut c_void;

/// OIDN_DEVICE_TYPE_CPU, OIDN_FORMAT_FLOAT3, OIDN_ERROR_NONE.
const DEVICE_CPU: c_int = 1;
const FORMAT_FLOAT3: c_int = 3;
const ERROR_NONE: c_int = 0;

const LIBRARY_NAME: &str = "libOpenImageDenoise.so.2";

/// The EXR layer of the denoised beauty.
pub const LAYER: &str = "denoised";

/// Where lucerna looks for the library, in order (existing files only, then the bare name
/// for the system's search path).
pub fn library_candidates() -> Vec<PathBuf> {
    let mut found = Vec::new();
    if let Some(p) = std::env::var_os("LUCERNA_OIDN").map(PathBuf::from) {
        found.push(if p.is_dir() { p.join(LIBRARY_NAME) } else { p });
    }
    for python in crate::install::known_pythons() {
        // VENV/bin/python -> VENV/lib/python3.X/site-packages/pyoidn/oidn/lib
        let Some(venv) = python.parent().and_then(Path::parent) else {
            continue;
        };
        let Ok(entries) = std::fs::read_dir(venv.join("lib")) else {
            continue;
        };
        for entry in entries.flatten() {
            let lib = entry
                .path()
                .join("site-packages/pyoidn/oidn/lib")
                .join(LIBRARY_NAME);
            if lib.exists() {
                found.push(lib);
            }
        }
    }
    found.push(LIBRARY_NAME.into());
    found
}

/// The loaded library and the device made with it.
pub struct Denoiser {
    library: Library,
    device: Device,
    /// The file the library was loaded from.
    pub path: PathBuf,
}

/// The layers of one denoising, as planes (row-major over `width` x `height`): the beauty
/// R, G, B, A, the albedo R, G, B and the normal X, Y, Z, as a film or an EXR holds them.
pub struct Layers<'a> {
    pub width: usize,
    pub height: usize,
    pub beauty: [&'a [f32]; 4],
    pub albedo: [&'a [f32]; 3],
    pub normal: [&'a [f32]; 3],
}

impl Denoiser {
    /// Loads the library (see the module doc) and makes a CPU device.
    pub fn new() -> Result<Self> {
        let mut tried = Vec::new();
        for path in library_candidates() {
            // SAFETY: loading OIDN runs its (and its dependencies') initialisers, which do
            // not depend on anything of this process.
            match unsafe { Library::new(&path) } {
                Ok(library) => return Self::with_library(library, path),
                Err(e) => tried.push(format!("{}: {e}", path.display())),
            }
        }
        Err(Error::bad_input(
            "",
            "--denoise",
            format!(
                "the Open Image Denoise library was not found; `lucerna setup` installs it (Python package pyoidn), or set LUCERNA_OIDN to {LIBRARY_NAME} (tried: {})",
                tried.join("; ")
            ),
        ))
    }

    fn with_library(library: Library, path: PathBuf) -> Result<Self> {
        let failed = |what: &str| Error::other(&path, "Open Image Denoise", what.to_string());
        // SAFETY: the symbols have the signatures of OIDN 2's C API (oidn.h).
        let device = unsafe {
            let new_device: Symbol<unsafe extern "C" fn(c_int) -> Device> = library
                .get(b"oidnNewDevice\0")
                .map_err(|e| failed(&e.to_string()))?;
            let commit: Symbol<unsafe extern "C" fn(Device)> =
                library
                    .get(b"oidnCommitDevice\0")
                    .map_err(|e| failed(&e.to_string()))?;
            let device = new_device(DEVICE_CPU);
            if device.is_null() {
                return Err(failed("no CPU device"));
            }
            commit(device);
            device
        };
        let denoiser = Self {
            library,
            device,
            path,
        };
        denoiser.check("the device")?;
        Ok(denoiser)
    }

    /// The device's pending error, if any.
    fn check(&self, during: &str) -> Result<()> {
        // SAFETY: OIDN's signature; the message pointer stays valid until the next call.
        unsafe {
            let get_error: Symbol<unsafe extern "C" fn(Device, *mut *const c_char) -> c_int> = self
                .library
                .get(b"oidnGetDeviceError\0")
                .map_err(|e| Error::other(&self.path, "Open Image Denoise", e.to_string()))?;
            let mut message: *const c_char = std::ptr::null();
            if get_error(self.device, &mut message) != ERROR_NONE {
                let text = if message.is_null() {
                    "unknown error".into()
                } else {
                    CStr::from_ptr(message).to_string_lossy().into_owned()
                };
                return Err(Error::other(
                    &self.path,
                    "Open Image Denoise",
                    format!("{during}: {text}"),
                ));
            }
        }
        Ok(())
    }

    /// Runs one `RT` filter: `images` (name, pixels) in, `output` out; `flags` are its
    /// boolean parameters.
    fn run(
        &self,
        (width, height): (usize, usize),
        images: &[(&str, &[f32])],
        output: &mut [f32],
        flags: &[(&str, bool)],
    ) -> Result<()> {
        let missing =
            |e: libloading::Error| Error::other(&self.path, "Open Image Denoise", e.to_string());
        type SetImage = unsafe extern "C" fn(
            Filter,
            *const c_char,
            *mut c_void,
            c_int,
            usize,
            usize,
            usize,
            usize,
            usize,
        );
        // SAFETY: OIDN 2's C API; every image is a live, host-memory buffer of
        // width * height * 3 floats (checked below) that outlives the filter's execution.
        unsafe {
            let new_filter: Symbol<unsafe extern "C" fn(Device, *const c_char) -> Filter> =
                self.library.get(b"oidnNewFilter\0").map_err(missing)?;
            let set_image: Symbol<SetImage> = self
                .library
                .get(b"oidnSetSharedFilterImage\0")
                .map_err(missing)?;
            let set_bool: Symbol<unsafe extern "C" fn(Filter, *const c_char, bool)> =
                self.library.get(b"oidnSetFilterBool\0").map_err(missing)?;
            let commit: Symbol<unsafe extern "C" fn(Filter)> =
                self.library.get(b"oidnCommitFilter\0").map_err(missing)?;
            let execute: Symbol<unsafe extern "C" fn(Filter)> =
                self.library.get(b"oidnExecuteFilter\0").map_err(missing)?;
            let release: Symbol<unsafe extern "C" fn(Filter)> =
                self.library.get(b"oidnReleaseFilter\0").map_err(missing)?;
            let n = width * height * 3;
            assert!(output.len() == n && images.iter().all(|(_, p)| p.len() == n));
            let filter = new_filter(self.device, c"RT".as_ptr());
            if filter.is_null() {
                self.check("making the RT filter")?;
                return Err(Error::other(
                    &self.path,
                    "Open Image Denoise",
                    "no RT filter",
                ));
            }
            let name = |s: &str| CString::new(s).expect("no NUL in a parameter name");
            let stride = 3 * std::mem::size_of::<f32>();
            for (image, pixels) in images {
                let image = name(image);
                set_image(
                    filter,
                    image.as_ptr(),
                    pixels.as_ptr() as *mut c_void,
                    FORMAT_FLOAT3,
                    width,
                    height,
                    0,
                    stride,
                    stride * width,
                );
            }
            let out = name("output");
            set_image(
                filter,
                out.as_ptr(),
                output.as_mut_ptr() as *mut c_void,
                FORMAT_FLOAT3,
                width,
                height,
                0,
                stride,
                stride * width,
            );
            for (flag, value) in flags {
                let flag = name(flag);
                set_bool(filter, flag.as_ptr(), *value);
            }
            commit(filter);
            let committed = self.check("setting up the filter");
            if committed.is_ok() {
                execute(filter);
            }
            release(filter);
            committed.and_then(|()| self.check("denoising"))
        }
    }

    /// The denoised beauty (row-major RGB), with prefiltered albedo and normal.
    pub fn denoise(&self, layers: &Layers) -> Result<[Vec<f32>; 3]> {
        let size = (layers.width, layers.height);
        let n = layers.width * layers.height * 3;
        let mut albedo = vec![0.0; n];
        let guide = albedo_guide(&layers.albedo, &layers.beauty);
        self.run(size, &[("albedo", &guide)], &mut albedo, &[])?;
        let mut normal = vec![0.0; n];
        let normals = crate::film::planes::interleave(&layers.normal);
        self.run(size, &[("normal", &normals)], &mut normal, &[])?;
        let mut output = vec![0.0; n];
        self.run(
            size,
            &[
                (
                    "color",
                    &crate::film::planes::interleave(&layers.beauty[..3]),
                ),
                ("albedo", &albedo),
                ("normal", &normal),
            ],
            &mut output,
            &[("hdr", true), ("cleanAux", true)],
        )?;
        Ok(std::array::from_fn(|c| {
            output.iter().skip(c).step_by(3).copied().collect()
        }))
    }
}

impl Drop for Denoiser {
    fn drop(&mut self) {
        // SAFETY: the device was made by this library and is released once.
        unsafe {
            if let Ok(release) = self
                .library
                .get::<unsafe extern "C" fn(Device)>(b"oidnReleaseDevice\0")
            {
                release(self.device);
            }
        }
    }
}

/// The albedo guide (row-major RGB): the albedo layer where paths hit a surface, and where
/// they left the scene (the uncovered fraction 1 - A of a pixel) the environment's colour
/// clamped to [0, 1], as OIDN's documentation asks for primary rays that hit no surface.
/// Without it a silhouette against a bright background has a black guide and its
/// antialiased edge is smeared.
fn albedo_guide(albedo: &[&[f32]; 3], beauty: &[&[f32]; 4]) -> Vec<f32> {
    let n = albedo[0].len();
    let mut rgb = Vec::with_capacity(n * 3);
    for i in 0..n {
        let uncovered = (1.0 - beauty[3][i]).clamp(0.0, 1.0);
        for c in 0..3 {
            rgb.push(albedo[c][i] + uncovered * beauty[c][i].clamp(0.0, 1.0));
        }
    }
    rgb
}

/// The EXR channels of a denoised beauty: `denoised.R`, `.G`, `.B`.
pub fn channels(rgb: [Vec<f32>; 3]) -> impl Iterator<Item = (String, Vec<f32>)> {
    ["R", "G", "B"]
        .into_iter()
        .zip(rgb)
        .map(|(c, plane)| (format!("{LAYER}.{c}"), plane))
}
