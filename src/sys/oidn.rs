//! Intel Open Image Denoise (OIDN 2.x): hand-written bindings of the few C functions the
//! denoiser calls, and a safe wrapper over them (a CPU device and one run of its "RT" filter).
//!
//! The library is opened at run time, not linked: only `--denoise` needs it, so a build or a
//! machine without it keeps every other command, and processes that never denoise do not pay
//! for loading its 50 MB core. Where it is looked for, in order:
//! - `$ICRENDER_OIDN_LIB`, alone when set: naming a library means that one or none, so a user
//!   never silently gets another one (and a test can make the library unfindable);
//! - `libOpenImageDenoise.so.2` beside the executable (and one folder up, for test binaries in
//!   target/<profile>/deps), for a binary copied elsewhere with the libraries beside it;
//! - the folder scripts/install-deps.sh unpacks the pinned wheel into, whose absolute path
//!   build.rs bakes in (ICRENDER_OIDN_DIR), the way an rpath would be.
//!
//! Its dependencies: libOpenImageDenoise.so.2 needs libOpenImageDenoise_core.so.2.5.1, which
//! loads the CPU device module from its own folder, which needs libtbb.so.12. The wheel's
//! libraries find each other through RPATH `$ORIGIN/../lib`, which holds only in a folder
//! called `lib`; so the core is opened first by its absolute path beside the library found, and
//! the loader then satisfies the library's NEEDED entry by soname with it, wherever it lies.
//! TBB: Debian's Embree links the system's libtbb.so.12 (oneTBB 2021.8), so icrender has a TBB
//! before OIDN is opened, and OIDN's CPU device uses that one (the 18 TBB symbols it imports are
//! all in 2021.8). Two TBBs in one process would be two schedulers, so the wheel's copy is
//! opened first only when no libtbb.so.12 is loaded yet.

use libloading::os::unix::{Library, RTLD_LAZY, RTLD_LOCAL, RTLD_NOW};
use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The file name (soname) of the library: OIDN 2.x.
pub const LIBRARY_NAME: &str = "libOpenImageDenoise.so.2";
/// The core library it needs, by soname (that of the pinned 2.5.1).
const CORE_NAME: &str = "libOpenImageDenoise_core.so.2.5.1";
const TBB_NAME: &str = "libtbb.so.12";

type Handle = *mut c_void;

// OIDN's C enums (oidn.h, 2.x), passed as C ints.
const DEVICE_TYPE_CPU: c_int = 1;
const FORMAT_FLOAT3: c_int = 3;
const ERROR_NONE: c_int = 0;

/// The entry points, copied out of the library, which stays open for the life of the process.
struct Api {
    new_device: unsafe extern "C" fn(c_int) -> Handle,
    set_device_int: unsafe extern "C" fn(Handle, *const c_char, c_int),
    get_device_int: unsafe extern "C" fn(Handle, *const c_char) -> c_int,
    commit_device: unsafe extern "C" fn(Handle),
    release_device: unsafe extern "C" fn(Handle),
    get_device_error: unsafe extern "C" fn(Handle, *mut *const c_char) -> c_int,
    new_filter: unsafe extern "C" fn(Handle, *const c_char) -> Handle,
    #[allow(clippy::type_complexity)]
    set_shared_filter_image:
        unsafe extern "C" fn(Handle, *const c_char, *mut c_void, c_int, usize, usize, usize, usize, usize),
    set_filter_bool: unsafe extern "C" fn(Handle, *const c_char, bool),
    set_filter_int: unsafe extern "C" fn(Handle, *const c_char, c_int),
    commit_filter: unsafe extern "C" fn(Handle),
    execute_filter: unsafe extern "C" fn(Handle),
    release_filter: unsafe extern "C" fn(Handle),
    path: PathBuf,
    /// Kept open: OIDN's threads and static objects live as long as the process.
    _libraries: Vec<Library>,
}

/// Where the library may be, in order (see the module's comment).
fn library_candidates() -> Vec<PathBuf> {
    if let Some(path) = std::env::var_os("ICRENDER_OIDN_LIB") {
        return vec![PathBuf::from(path)];
    }
    let mut paths = super::beside_executable(LIBRARY_NAME);
    paths.push(Path::new(env!("ICRENDER_OIDN_DIR")).join(LIBRARY_NAME));
    paths
}

/// Whether the process already has a library of this soname (without loading it).
fn already_loaded(soname: &str) -> bool {
    // SAFETY: RTLD_NOLOAD only looks the name up among loaded objects; it runs no code.
    unsafe { Library::open(Some(soname), RTLD_LAZY | RTLD_LOCAL | libc::RTLD_NOLOAD) }.is_ok()
}

/// Opens the library at `path` after the dependencies beside it (see the module's comment).
fn open_at(path: &Path) -> Result<Api, String> {
    let folder = path.parent().unwrap_or(Path::new("."));
    let mut libraries = Vec::new();
    let mut first = vec![folder.join(CORE_NAME)];
    if !already_loaded(TBB_NAME) {
        first.insert(0, folder.join(TBB_NAME));
    }
    for dependency in first.iter().filter(|p| p.is_file()) {
        // SAFETY: the wheel's own libraries; opening them runs their static constructors only.
        let library = unsafe { Library::open(Some(dependency), RTLD_NOW | RTLD_LOCAL) }.map_err(|e| e.to_string())?;
        libraries.push(library);
    }
    // SAFETY: as above.
    let library = unsafe { Library::open(Some(path), RTLD_NOW | RTLD_LOCAL) }.map_err(|e| e.to_string())?;
    // SAFETY: each field's type is the signature oidn.h (OIDN 2.x) declares for the function
    // of that name, and `symbol` checks that the library has it.
    let mut api = unsafe {
        Api {
            new_device: symbol(&library, "oidnNewDevice")?,
            set_device_int: symbol(&library, "oidnSetDeviceInt")?,
            get_device_int: symbol(&library, "oidnGetDeviceInt")?,
            commit_device: symbol(&library, "oidnCommitDevice")?,
            release_device: symbol(&library, "oidnReleaseDevice")?,
            get_device_error: symbol(&library, "oidnGetDeviceError")?,
            new_filter: symbol(&library, "oidnNewFilter")?,
            set_shared_filter_image: symbol(&library, "oidnSetSharedFilterImage")?,
            set_filter_bool: symbol(&library, "oidnSetFilterBool")?,
            set_filter_int: symbol(&library, "oidnSetFilterInt")?,
            commit_filter: symbol(&library, "oidnCommitFilter")?,
            execute_filter: symbol(&library, "oidnExecuteFilter")?,
            release_filter: symbol(&library, "oidnReleaseFilter")?,
            path: path.to_path_buf(),
            _libraries: Vec::new(),
        }
    };
    libraries.push(library);
    api._libraries = libraries;
    Ok(api)
}

/// The function `name` of `library`, as a function pointer of type `T`.
///
/// # Safety
/// `T` must be the function's true signature.
unsafe fn symbol<T: Copy>(library: &Library, name: &str) -> Result<T, String> {
    let c = c_name(name);
    // SAFETY: guaranteed by the caller.
    unsafe { library.get::<T>(c.as_bytes_with_nul()) }
        .map(|s| *s)
        .map_err(|e| format!("{name}: {e}"))
}

fn open_library() -> Result<Api, String> {
    let candidates = library_candidates();
    let mut failures = Vec::new();
    for path in &candidates {
        if !path.is_file() {
            continue;
        }
        match open_at(path) {
            Ok(api) => return Ok(api),
            Err(e) => failures.push(format!("{}: {e}", path.display())),
        }
    }
    if failures.is_empty() {
        if let Some(named) = std::env::var_os("ICRENDER_OIDN_LIB") {
            return Err(format!(
                "the denoiser library {LIBRARY_NAME} was not found at {}, which ICRENDER_OIDN_LIB names \
                 (unset it to look beside icrender and where scripts/install-deps.sh unpacks it)",
                Path::new(&named).display()
            ));
        }
        let looked: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
        Err(format!(
            "the denoiser library {LIBRARY_NAME} (Intel Open Image Denoise 2) was not found (looked for {}); \
             run scripts/install-deps.sh, or set ICRENDER_OIDN_LIB to the library",
            looked.join(", ")
        ))
    } else {
        Err(format!(
            "the denoiser library could not be opened: {}",
            failures.join("; ")
        ))
    }
}

/// The library, opened on first use and kept for the life of the process.
fn api() -> Result<&'static Api, String> {
    static API: OnceLock<Result<Api, String>> = OnceLock::new();
    API.get_or_init(open_library).as_ref().map_err(Clone::clone)
}

fn c_name(name: &str) -> CString {
    CString::new(name).expect("parameter names have no NUL")
}

/// The filter's quality setting (OIDN_QUALITY_*): the trade of its time against its error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quality {
    Fast,
    Balanced,
    High,
}

impl Quality {
    fn code(self) -> c_int {
        match self {
            Quality::Fast => 4,
            Quality::Balanced => 5,
            Quality::High => 6,
        }
    }
}

/// One run of the "RT" filter. Planes are 3 floats a pixel, rows top to bottom. With `color`
/// it denoises the colour, guided by whichever auxiliary planes are given; without it, it
/// prefilters the one auxiliary plane given (OIDN's way to clean a noisy guide).
pub struct RtFilter<'a> {
    pub width: usize,
    pub height: usize,
    pub color: Option<&'a [f32]>,
    pub albedo: Option<&'a [f32]>,
    pub normal: Option<&'a [f32]>,
    /// The colour is linear HDR (any non-negative value), not [0, 1].
    pub hdr: bool,
    /// The auxiliary planes are clean (prefiltered): the filter keeps what they show. Off, it
    /// takes them as guides that may be noisy.
    pub clean_aux: bool,
    pub quality: Quality,
}

impl RtFilter<'_> {
    fn check(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "cannot denoise an image of {}x{} pixels",
                self.width, self.height
            ));
        }
        let floats = 3 * self.width * self.height;
        for (name, plane) in [("color", self.color), ("albedo", self.albedo), ("normal", self.normal)] {
            if let Some(plane) = plane
                && plane.len() != floats
            {
                return Err(format!(
                    "the {name} plane has {} values for {}x{} pixels of 3",
                    plane.len(),
                    self.width,
                    self.height
                ));
            }
        }
        let aux = self.albedo.is_some() as usize + self.normal.is_some() as usize;
        if self.color.is_none() && aux != 1 {
            return Err("without a colour plane the filter prefilters exactly one guide".into());
        }
        if self.color.is_some() && self.normal.is_some() && self.albedo.is_none() {
            return Err("OIDN takes a normal guide only together with an albedo guide".into());
        }
        Ok(())
    }
}

/// An OIDN CPU device, committed. Not shared between threads (OIDN serialises a device's calls
/// anyway, and the denoiser runs once, after rendering).
pub struct Device {
    api: &'static Api,
    raw: Handle,
}

impl Device {
    /// Opens the library (once per process) and commits a CPU device with `threads` threads
    /// (None: OIDN's default, every core).
    pub fn new(threads: Option<usize>) -> Result<Device, String> {
        let api = api()?;
        // SAFETY: a plain call; a NULL result is handled below.
        let raw = unsafe { (api.new_device)(DEVICE_TYPE_CPU) };
        if raw.is_null() {
            return Err(format!(
                "Open Image Denoise could not create a CPU device: {}",
                error_of(api, std::ptr::null_mut()).unwrap_or_else(|| "no reason given".into())
            ));
        }
        let device = Device { api, raw };
        if let Some(threads) = threads {
            let name = c_name("numThreads");
            let threads = c_int::try_from(threads).unwrap_or(c_int::MAX);
            // SAFETY: a live device and a NUL-terminated parameter name.
            unsafe { (api.set_device_int)(raw, name.as_ptr(), threads) };
        }
        // SAFETY: a live device.
        unsafe { (api.commit_device)(raw) };
        device.check("committing its CPU device")?;
        Ok(device)
    }

    /// Where the library was opened from.
    pub fn library_path(&self) -> &Path {
        &self.api.path
    }

    /// The library's version, as "2.5.1".
    pub fn version(&self) -> String {
        let name = c_name("version");
        // SAFETY: a live, committed device and a NUL-terminated parameter name.
        let v = unsafe { (self.api.get_device_int)(self.raw, name.as_ptr()) };
        format!("{}.{}.{}", v / 10000, v / 100 % 100, v % 100)
    }

    /// The first error the device holds for this thread, as an Err naming `doing`.
    fn check(&self, doing: &str) -> Result<(), String> {
        match error_of(self.api, self.raw) {
            None => Ok(()),
            Some(message) => Err(format!("Open Image Denoise failed {doing}: {message}")),
        }
    }

    /// Runs the filter and returns its output plane (3 floats a pixel).
    pub fn run(&self, filter: &RtFilter<'_>) -> Result<Vec<f32>, String> {
        filter.check()?;
        let mut output = vec![0.0f32; 3 * filter.width * filter.height];
        let api = self.api;
        let type_name = c_name("RT");
        // SAFETY: a live device and a NUL-terminated type name; NULL is handled below.
        let raw = unsafe { (api.new_filter)(self.raw, type_name.as_ptr()) };
        if raw.is_null() {
            self.check("creating its RT filter")?;
            return Err("Open Image Denoise could not create its RT filter".into());
        }
        struct FilterHandle(&'static Api, Handle);
        impl Drop for FilterHandle {
            fn drop(&mut self) {
                // SAFETY: the handle came from oidnNewFilter and is released once.
                unsafe { (self.0.release_filter)(self.1) };
            }
        }
        let handle = FilterHandle(api, raw);
        let image = |name: &str, data: *mut f32| {
            let name = c_name(name);
            // SAFETY: `data` holds width * height packed float3 pixels (checked above) and
            // outlives the filter, which `handle` releases before this function returns; the
            // strides 0 mean packed. OIDN only reads the input planes (the pointer is mutable
            // in its API because the same call sets the output).
            unsafe {
                (api.set_shared_filter_image)(
                    handle.1,
                    name.as_ptr(),
                    data.cast(),
                    FORMAT_FLOAT3,
                    filter.width,
                    filter.height,
                    0,
                    0,
                    0,
                )
            };
        };
        for (name, plane) in [
            ("color", filter.color),
            ("albedo", filter.albedo),
            ("normal", filter.normal),
        ] {
            if let Some(plane) = plane {
                image(name, plane.as_ptr().cast_mut());
            }
        }
        image("output", output.as_mut_ptr());
        let set_bool = |name: &str, value: bool| {
            let name = c_name(name);
            // SAFETY: a live filter and a NUL-terminated parameter name.
            unsafe { (api.set_filter_bool)(handle.1, name.as_ptr(), value) };
        };
        if filter.color.is_some() {
            set_bool("hdr", filter.hdr);
            set_bool("cleanAux", filter.clean_aux);
        }
        let quality = c_name("quality");
        // SAFETY: a live filter and a NUL-terminated parameter name.
        unsafe { (api.set_filter_int)(handle.1, quality.as_ptr(), filter.quality.code()) };
        // SAFETY: a live filter whose images are all set and alive.
        unsafe { (api.commit_filter)(handle.1) };
        self.check("setting up its RT filter")?;
        // SAFETY: as above; the call returns when the output is written (synchronous).
        unsafe { (api.execute_filter)(handle.1) };
        self.check("running its RT filter")?;
        drop(handle);
        Ok(output)
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the handle came from oidnNewDevice and is released once, after its filters.
        unsafe { (self.api.release_device)(self.raw) };
    }
}

/// The first unqueried error of `device` (NULL: of the last device creation on this thread).
fn error_of(api: &Api, device: Handle) -> Option<String> {
    let mut message: *const c_char = std::ptr::null();
    // SAFETY: `device` is live or NULL (allowed); the message, if any, is a NUL-terminated
    // string valid until the next OIDN call on this thread, and is copied at once.
    let code = unsafe { (api.get_device_error)(device, &mut message) };
    if code == ERROR_NONE {
        return None;
    }
    let text = if message.is_null() {
        String::new()
    } else {
        // SAFETY: see above.
        unsafe { CStr::from_ptr(message) }.to_string_lossy().into_owned()
    };
    Some(if text.is_empty() {
        format!("error code {code}")
    } else {
        text
    })
}
