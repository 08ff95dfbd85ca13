//! The Embree backend: the system Embree (3.13 on Debian; Embree 4 when its headers are
//! found, `cfg(embree4)`, e.g. the installation `scripts/embree4.sh` assembles) through
//! the bindings `build.rs` generates from `wrapper.h`. [`version`] reports the library
//! linked at run time.
//!
//! With the raw bindings ([`crate::ffi::embree`]) and the OpenImageIO bridge, the only
//! code of the crate with `unsafe`. Ownership is RAII: [`Device`],
//! [`EmbreeScene`] and the geometries release their Embree handles on `Drop`. Errors that
//! Embree reports through the device error callback are collected and returned as
//! [`AccelError::Embree`]; nothing aborts.
use crate::accel::query::{
    AccelError, BuildOptions, BuildQuality, BvhLayout, Cutout, Cutouts, Geometry, Hit, Ray, keeps_hit,
};
use std::ffi::{CStr, c_char, c_void};
use std::ptr;
use std::sync::{Arc, Mutex};

use crate::ffi::embree as ffi;

/// Sets the calling thread's SSE control register to flush denormals to zero and treat
/// denormal inputs as zero (FTZ/DAZ), as Embree recommends for its traversal kernels.
/// A render's worker threads call it once, when they start ([`crate::workers::render_pool`]);
/// results change only for values below 1e-38.
#[inline]
pub fn set_flush_denormals() {
    #[cfg(target_arch = "x86_64")]
    {
        const FTZ_DAZ: u32 = (1 << 15) | (1 << 6);
        let mut csr: u32 = 0;
        // SAFETY: `stmxcsr`/`ldmxcsr` read and write the calling thread's MXCSR register
        // through a valid 4-byte stack slot; setting FTZ and DAZ only changes how denormal
        // floats are rounded and is allowed on every x86-64 CPU (SSE2 is baseline).
        unsafe {
            std::arch::asm!("stmxcsr [{0}]", in(reg) &mut csr, options(nostack, preserves_flags));
            let new = csr | FTZ_DAZ;
            if new != csr {
                std::arch::asm!("ldmxcsr [{0}]", in(reg) &new, options(nostack, preserves_flags));
            }
        }
    }
}

/// The filter function of a geometry with a cut-out, for intersection and occlusion
/// queries alike (Embree 3 and 4 pass the same arguments): a candidate hit that
/// [`keeps_hit`] does not keep is marked invalid, so Embree goes on as if the ray had
/// missed it. The hash sees the ray's origin and direction as the caller gave them, so a
/// query gets the answer the obvhs backend gives.
unsafe extern "C" fn cutout_filter(args: *const ffi::RTCFilterFunctionNArguments) {
    // SAFETY: Embree passes valid arguments for the duration of the call: `valid` points to
    // `N` ints, `ray` and `hit` to `N`-wide structures of arrays (`RTCRayN`, `RTCHitN`:
    // field `k` of lane `i` is 4-byte item `k N + i`, the layout of Embree's `RTCRayN_*` and
    // `RTCHitN_*` accessors), and the user pointer is the `Arc<dyn Cutout>` set in
    // `new_geometry`, alive as long as the scene. The cut-out's lookup does not panic (its
    // indices come from the mesh the geometry was built from).
    unsafe {
        let args = &*args;
        let cutout = &*(args.geometryUserPtr as *const Arc<dyn Cutout>);
        let n = args.N as usize;
        let ray = args.ray as *const f32;
        let hit = args.hit as *const f32;
        for i in 0..n {
            let valid = args.valid.add(i);
            if *valid == 0 {
                continue;
            }
            let r = |k: usize| *ray.add(k * n + i);
            let query = Ray {
                o: glam::Vec3::new(r(0), r(1), r(2)),
                d: glam::Vec3::new(r(4), r(5), r(6)),
                tmin: r(3),
                tmax: r(8),
            };
            let (u, v) = (*hit.add(3 * n + i), *hit.add(4 * n + i));
            let prim = *(hit as *const u32).add(5 * n + i);
            let geom = *(hit as *const u32).add(6 * n + i);
            if !keeps_hit(cutout.as_ref(), &query, geom, prim, u, v) {
                *valid = 0;
            }
        }
    }
}

/// `RTC_INVALID_GEOMETRY_ID` (a cast macro that bindgen does not translate).
const INVALID_ID: u32 = u32::MAX;

/// The Embree version of the headers the bindings were generated from (`RTC_VERSION`,
/// `10000 major + 100 minor + patch`).
pub const HEADERS_VERSION: u32 = ffi::RTC_VERSION;

/// Whether the crate was built against Embree 4 headers (`cfg(embree4)`).
pub const EMBREE4: bool = cfg!(embree4);

/// An Embree version number.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Version {
    pub major: u32,
    pub minor: u32,
    pub patch: u32,
}

impl Version {
    /// Splits Embree's `10000 major + 100 minor + patch`.
    pub fn from_number(n: u32) -> Version {
        Version { major: n / 10000, minor: n / 100 % 100, patch: n % 100 }
    }
}

impl std::fmt::Display for Version {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

/// The version of the Embree library linked at run time (`RTC_DEVICE_PROPERTY_VERSION` of
/// a new device).
pub fn version() -> Result<Version, AccelError> {
    let device = Device::new(None)?;
    // SAFETY: `device.raw` is a live device; the property is a plain integer query.
    let n = unsafe { ffi::rtcGetDeviceProperty(device.raw, ffi::RTCDeviceProperty::RTC_DEVICE_PROPERTY_VERSION) };
    device.check("rtcGetDeviceProperty")?;
    let n = u32::try_from(n).map_err(|_| AccelError::Embree(format!("Embree reports version {n}")))?;
    Ok(Version::from_number(n))
}

/// Messages the device error callback has collected since the last check.
type ErrorLog = Mutex<Vec<String>>;

unsafe extern "C" fn error_callback(user: *mut c_void, code: ffi::RTCError, message: *const c_char) {
    // SAFETY: `user` is the `ErrorLog` owned by the `Device` that registered this callback;
    // the device outlives every call Embree makes on it. `message` is a NUL-terminated
    // string owned by Embree for the duration of the call, or null.
    let (log, text) = unsafe {
        let log = &*(user as *const ErrorLog);
        let text =
            if message.is_null() { String::new() } else { CStr::from_ptr(message).to_string_lossy().into_owned() };
        (log, text)
    };
    if let Ok(mut log) = log.lock() {
        log.push(format!("{code:?}: {text}"));
    }
}

/// An Embree device with its error log.
pub struct Device {
    raw: ffi::RTCDevice,
    errors: Box<ErrorLog>,
}

// SAFETY: an Embree device is internally synchronised; we only create scenes from it on one
// thread at a time (building takes `&self` but is not shared across threads here) and read
// the error log through a mutex.
unsafe impl Send for Device {}
// SAFETY: see `Send`; all shared access goes through Embree's thread-safe API or the mutex.
unsafe impl Sync for Device {}

/// The environment variable whose Embree device configuration every device gets (before
/// the `--embree-config` option's): `PCBPT_EMBREE_CONFIG=max_isa=sse4.2 cargo test` runs the
/// kernels an older CPU would.
pub const CONFIG_ENV: &str = "PCBPT_EMBREE_CONFIG";

/// The configuration string a device is created with: `verbose=0`, then the
/// `PCBPT_EMBREE_CONFIG` environment variable's pairs, then `extra`'s (Embree reads them in
/// order, so a later value of a key wins). Embree's keys include `isa=` and `max_isa=`
/// (`sse2`, `sse4.2`, `avx`, `avx2`, `avx512`), which pick the kernels another CPU would
/// run, `threads=` (build threads) and `verbose=` (1 prints the ISA Embree selected).
/// Embree ignores keys it does not know; what is not a `key=value` pair, or names an
/// unknown instruction set, is refused here.
pub fn device_config(extra: Option<&str>) -> Result<String, AccelError> {
    let env = std::env::var(CONFIG_ENV).ok();
    config_string(env.as_deref(), extra)
}

/// The instruction sets Embree 3.13 and 4 dispatch to on x86-64, as `isa=`/`max_isa=` name them.
const ISAS: [&str; 5] = ["sse2", "sse4.2", "avx", "avx2", "avx512"];

fn config_string(env: Option<&str>, extra: Option<&str>) -> Result<String, AccelError> {
    let mut config = String::from("verbose=0");
    for (source, part) in [(CONFIG_ENV, env), ("--embree-config", extra)] {
        let Some(part) = part.map(str::trim).filter(|p| !p.is_empty()) else { continue };
        // Embree ignores what it does not understand without an error: refuse what is not
        // a list of `key=value` pairs here, so a typo is not silently dropped.
        for pair in part.split(',').map(str::trim) {
            let ok = pair.split_once('=').is_some_and(|(k, v)| {
                !k.is_empty()
                    && !v.is_empty()
                    && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                    && v.chars().all(|c| c.is_ascii_alphanumeric() || "._-".contains(c))
            });
            if !ok {
                return Err(AccelError::Embree(format!(
                    "{source}: `{pair}` is not a `key=value` pair of Embree's device configuration (e.g. max_isa=avx2)"
                )));
            }
            // Embree accepts an instruction set it does not know without an error (checked:
            // `max_isa=bogus` renders with the machine's best kernels).
            if let Some((key @ ("isa" | "max_isa"), value)) = pair.split_once('=')
                && !ISAS.contains(&value)
            {
                return Err(AccelError::Embree(format!(
                    "{source}: unknown instruction set `{key}={value}` (one of {})",
                    ISAS.join(", ")
                )));
            }
            config.push(',');
            config.push_str(pair);
        }
    }
    Ok(config)
}

impl Device {
    /// A device with [`device_config`]`(extra)` as its configuration.
    pub fn new(extra: Option<&str>) -> Result<Arc<Device>, AccelError> {
        let config = device_config(extra)?;
        let c_config = std::ffi::CString::new(config.as_str())
            .map_err(|_| AccelError::Embree(format!("device configuration `{config}` contains a NUL byte")))?;
        // SAFETY: the configuration string is a valid NUL-terminated C string that outlives
        // the call (Embree copies what it keeps).
        let raw = unsafe { ffi::rtcNewDevice(c_config.as_ptr()) };
        if raw.is_null() {
            // SAFETY: querying the error of a null device is allowed and returns the last
            // device-creation error.
            let code = unsafe { ffi::rtcGetDeviceError(ptr::null_mut()) };
            return Err(AccelError::Embree(format!("rtcNewDevice(\"{config}\") failed ({code:?})")));
        }
        let errors: Box<ErrorLog> = Box::new(Mutex::new(Vec::new()));
        // SAFETY: `raw` is a live device; the user pointer points into a Box that lives as
        // long as the `Device` (the box's heap address is stable when the struct moves).
        unsafe {
            ffi::rtcSetDeviceErrorFunction(raw, Some(error_callback), &*errors as *const ErrorLog as *mut c_void);
        }
        Ok(Arc::new(Device { raw, errors }))
    }

    /// Turns errors collected by the callback (or pending on the device) into a Rust error.
    fn check(&self, what: &str) -> Result<(), AccelError> {
        // SAFETY: `self.raw` is a live device.
        let code = unsafe { ffi::rtcGetDeviceError(self.raw) };
        let mut log = self.errors.lock().map_err(|_| AccelError::Embree("error log poisoned".into()))?;
        if !log.is_empty() || code != ffi::RTCError::RTC_ERROR_NONE {
            let mut messages: Vec<String> = log.drain(..).collect();
            if messages.is_empty() {
                messages.push(format!("{code:?}"));
            }
            return Err(AccelError::Embree(format!("{what}: {}", messages.join("; "))));
        }
        Ok(())
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: `self.raw` was returned by `rtcNewDevice` and is released exactly once;
        // scenes keep an `Arc<Device>`, so none outlives it.
        unsafe { ffi::rtcReleaseDevice(self.raw) }
    }
}

/// A geometry handle, released on drop (the scene keeps its own reference once attached).
struct GeometryHandle(ffi::RTCGeometry);

impl Drop for GeometryHandle {
    fn drop(&mut self) {
        // SAFETY: the handle came from `rtcNewGeometry` and is released exactly once.
        unsafe { ffi::rtcReleaseGeometry(self.0) }
    }
}

/// A committed Embree scene.
///
/// `Send + Sync`: after `rtcCommitScene` Embree allows any number of threads to call
/// `rtcIntersect*`/`rtcOccluded*` on the scene at once, and this type offers no way to
/// modify the scene after it is committed (every method takes `&self` and only queries).
pub struct EmbreeScene {
    raw: ffi::RTCScene,
    device: Arc<Device>,
    /// The cut-outs the geometries' filter functions read through their user pointers
    /// (boxed, so each address is stable); dropped after the scene is released.
    #[allow(clippy::vec_box)] // Embree holds the address of each boxed `Arc`.
    cutouts: Vec<Box<Arc<dyn Cutout>>>,
}

// SAFETY: see the type's documentation: a committed scene is immutable and Embree's query
// functions are thread-safe.
unsafe impl Send for EmbreeScene {}
// SAFETY: as above.
unsafe impl Sync for EmbreeScene {}

impl Drop for EmbreeScene {
    fn drop(&mut self) {
        // SAFETY: `self.raw` came from `rtcNewScene` and is released exactly once; the device
        // is kept alive by `self.device` until after this call.
        unsafe { ffi::rtcReleaseScene(self.raw) }
    }
}

fn quality(q: BuildQuality) -> ffi::RTCBuildQuality {
    match q {
        BuildQuality::Low => ffi::RTCBuildQuality::RTC_BUILD_QUALITY_LOW,
        BuildQuality::Medium => ffi::RTCBuildQuality::RTC_BUILD_QUALITY_MEDIUM,
        BuildQuality::High => ffi::RTCBuildQuality::RTC_BUILD_QUALITY_HIGH,
    }
}

impl EmbreeScene {
    /// Builds and commits a scene; geometry `i` gets geometry id `i`.
    pub fn build(
        geometry: &[Geometry<'_>],
        cutouts: &Cutouts,
        options: &BuildOptions,
    ) -> Result<EmbreeScene, AccelError> {
        let device = Device::new(options.embree_config.as_deref())?;
        // SAFETY: `device.raw` is a live device.
        let raw = unsafe { ffi::rtcNewScene(device.raw) };
        if raw.is_null() {
            device.check("rtcNewScene")?;
            return Err(AccelError::Embree("rtcNewScene returned null".into()));
        }
        let mut scene = EmbreeScene { raw, device, cutouts: Vec::new() };
        let mut flags = ffi::RTCSceneFlags::RTC_SCENE_FLAG_NONE;
        if options.robust {
            flags |= ffi::RTCSceneFlags::RTC_SCENE_FLAG_ROBUST;
        }
        if options.compact {
            flags |= ffi::RTCSceneFlags::RTC_SCENE_FLAG_COMPACT;
        }
        // Embree builds a scene of low build quality as two levels (a BVH per geometry, at
        // the geometry's own build quality, under a BVH over the geometries); medium and high
        // give one BVH over all primitives, so a flat layout has no low-quality build.
        let scene_quality = match (options.layout, options.quality) {
            (BvhLayout::TwoLevel, _) => ffi::RTCBuildQuality::RTC_BUILD_QUALITY_LOW,
            (BvhLayout::Flat, BuildQuality::Low) => {
                return Err(AccelError::Unsupported(
                    "Embree has no low-quality build of a flat BVH (its low-quality scene build is the two-level layout): use --bvh-layout two-level or a higher --bvh-quality",
                ));
            }
            (BvhLayout::Flat, q) => quality(q),
        };
        // SAFETY: `scene.raw` is a live, not yet committed scene.
        unsafe {
            ffi::rtcSetSceneFlags(scene.raw, flags);
            ffi::rtcSetSceneBuildQuality(scene.raw, scene_quality);
        }
        for (id, g) in geometry.iter().enumerate() {
            let cutout = cutouts.iter().find(|(c, _)| *c as usize == id).map(|(_, c)| Box::new(c.clone()));
            let handle = scene.new_geometry(g, options.quality, cutout.as_deref())?;
            scene.cutouts.extend(cutout);
            // SAFETY: both handles are live; the id is unique because it is the index.
            unsafe { ffi::rtcAttachGeometryByID(scene.raw, handle.0, id as u32) };
            scene.device.check("rtcAttachGeometryByID")?;
        }
        // SAFETY: every attached geometry is committed; building happens on this thread.
        unsafe { ffi::rtcCommitScene(scene.raw) };
        scene.device.check("rtcCommitScene")?;
        Ok(scene)
    }

    /// A committed geometry; with a cut-out, its intersection and occlusion filter functions
    /// skip the hits [`keeps_hit`] does not keep. `cutout` must stay where it is for as long
    /// as the scene lives (`self.cutouts` holds it).
    fn new_geometry(
        &self,
        g: &Geometry<'_>,
        q: BuildQuality,
        cutout: Option<&Arc<dyn Cutout>>,
    ) -> Result<GeometryHandle, AccelError> {
        let kind = match g {
            Geometry::Triangles { .. } => ffi::RTCGeometryType::RTC_GEOMETRY_TYPE_TRIANGLE,
            Geometry::Sphere { .. } => ffi::RTCGeometryType::RTC_GEOMETRY_TYPE_SPHERE_POINT,
            // Round, not flat: a real surface (a tube of constant radius, the cylinders of
            // Mitsuba 0.6's hair with spheres at the joints), the same for every ray. A flat
            // curve is a ribbon facing each ray, so a light path and a camera path would see
            // different surfaces, and Embree 3.13 skips flat-curve hits near the ray origin.
            // The same call and constant in Embree 3.13 and 4.
            Geometry::Curves { .. } => ffi::RTCGeometryType::RTC_GEOMETRY_TYPE_ROUND_LINEAR_CURVE,
        };
        // SAFETY: the device is live.
        let raw = unsafe { ffi::rtcNewGeometry(self.device.raw, kind) };
        self.device.check("rtcNewGeometry")?;
        if raw.is_null() {
            return Err(AccelError::Embree("rtcNewGeometry returned null".into()));
        }
        let handle = GeometryHandle(raw);
        match g {
            Geometry::Triangles { positions, indices } => {
                // Embree reads vertices with 16-byte loads: a buffer it allocates itself
                // (`rtcSetNewGeometryBuffer`) carries the padding it needs.
                let verts = self.new_buffer::<[f32; 3]>(
                    &handle,
                    ffi::RTCBufferType::RTC_BUFFER_TYPE_VERTEX,
                    ffi::RTCFormat::RTC_FORMAT_FLOAT3,
                    positions.len(),
                )?;
                for (dst, p) in verts.iter_mut().zip(positions.iter()) {
                    *dst = p.to_array();
                }
                let tris = self.new_buffer::<[u32; 3]>(
                    &handle,
                    ffi::RTCBufferType::RTC_BUFFER_TYPE_INDEX,
                    ffi::RTCFormat::RTC_FORMAT_UINT3,
                    indices.len(),
                )?;
                tris.copy_from_slice(indices);
            }
            Geometry::Sphere { center, radius } => {
                let v = self.new_buffer::<[f32; 4]>(
                    &handle,
                    ffi::RTCBufferType::RTC_BUFFER_TYPE_VERTEX,
                    ffi::RTCFormat::RTC_FORMAT_FLOAT4,
                    1,
                )?;
                v[0] = [center.x, center.y, center.z, *radius];
            }
            Geometry::Curves { vertices, segments, flags, radius } => {
                let v = self.new_buffer::<[f32; 4]>(
                    &handle,
                    ffi::RTCBufferType::RTC_BUFFER_TYPE_VERTEX,
                    ffi::RTCFormat::RTC_FORMAT_FLOAT4,
                    vertices.len(),
                )?;
                for (dst, p) in v.iter_mut().zip(vertices.iter()) {
                    *dst = [p.x, p.y, p.z, *radius];
                }
                let index = self.new_buffer::<u32>(
                    &handle,
                    ffi::RTCBufferType::RTC_BUFFER_TYPE_INDEX,
                    ffi::RTCFormat::RTC_FORMAT_UINT,
                    segments.len(),
                )?;
                index.copy_from_slice(segments);
                let f = self.new_buffer::<u8>(
                    &handle,
                    ffi::RTCBufferType::RTC_BUFFER_TYPE_FLAGS,
                    ffi::RTCFormat::RTC_FORMAT_UCHAR,
                    flags.len(),
                )?;
                f.copy_from_slice(flags);
            }
        }
        if let Some(c) = cutout {
            // SAFETY: the geometry is live and not committed; the user pointer points to an
            // `Arc<dyn Cutout>` in a box the scene keeps until after it is released (the
            // geometry lives no longer than the scene), and `cutout_filter` only reads it.
            unsafe {
                ffi::rtcSetGeometryUserData(handle.0, c as *const Arc<dyn Cutout> as *mut c_void);
                ffi::rtcSetGeometryIntersectFilterFunction(handle.0, Some(cutout_filter));
                ffi::rtcSetGeometryOccludedFilterFunction(handle.0, Some(cutout_filter));
            }
            self.device.check("rtcSetGeometryIntersectFilterFunction")?;
        }
        // SAFETY: the geometry is live and its buffers are filled.
        unsafe {
            ffi::rtcSetGeometryBuildQuality(handle.0, quality(q));
            ffi::rtcCommitGeometry(handle.0);
        }
        self.device.check("rtcCommitGeometry")?;
        Ok(handle)
    }

    /// A new Embree-owned buffer of `count` items of `T`, as a mutable slice.
    #[allow(clippy::mut_from_ref)]
    fn new_buffer<'g, T: Copy>(
        &self,
        geom: &'g GeometryHandle,
        kind: ffi::RTCBufferType,
        format: ffi::RTCFormat,
        count: usize,
    ) -> Result<&'g mut [T], AccelError> {
        // SAFETY: the geometry is live and not committed; slot 0 is valid for every buffer
        // type used here (vertices, indices, curve flags); the stride is the item size.
        let ptr = unsafe { ffi::rtcSetNewGeometryBuffer(geom.0, kind, 0, format, size_of::<T>(), count) };
        self.device.check("rtcSetNewGeometryBuffer")?;
        if ptr.is_null() {
            return Err(AccelError::Embree("rtcSetNewGeometryBuffer returned null".into()));
        }
        // SAFETY: Embree allocated `count * size_of::<T>()` bytes (plus padding), aligned to
        // at least 16 bytes (so for any `T` used here: `[f32; N]`, `[u32; 3]`, `u32`, `u8`), owned by the geometry, which lives as long as `'g` and is only
        // written through this slice before commit.
        Ok(unsafe { std::slice::from_raw_parts_mut(ptr as *mut T, count) })
    }

    #[cfg(not(embree4))]
    fn context(coherent: bool) -> ffi::RTCIntersectContext {
        // `rtcInitIntersectContext` is a header-only inline function that the library does
        // not export: this is its body for RTC_MAX_INSTANCE_LEVEL_COUNT = 1 (bindgen's
        // layout test guards the struct shape).
        ffi::RTCIntersectContext {
            flags: if coherent {
                ffi::RTC_INTERSECT_CONTEXT_FLAG_COHERENT
            } else {
                ffi::RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT
            },
            filter: None,
            instID: [INVALID_ID; 1],
        }
    }

    /// Embree 4's `rtcInitIntersectArguments` (a header-only inline function that the
    /// library does not export) with the coherence flag set as the Embree 3 context is:
    /// the default features, no query context, no callbacks. For RTC_MIN_WIDTH = 0: headers
    /// of an Embree built with min-width have one more field, and this literal does not
    /// compile against them.
    #[cfg(embree4)]
    fn intersect_args(coherent: bool) -> ffi::RTCIntersectArguments {
        ffi::RTCIntersectArguments {
            flags: Self::query_flags(coherent),
            feature_mask: ffi::RTC_FEATURE_FLAG_ALL,
            context: ptr::null_mut(),
            filter: None,
            intersect: None,
        }
    }

    /// `rtcInitOccludedArguments`, as [`Self::intersect_args`].
    #[cfg(embree4)]
    fn occluded_args(coherent: bool) -> ffi::RTCOccludedArguments {
        ffi::RTCOccludedArguments {
            flags: Self::query_flags(coherent),
            feature_mask: ffi::RTC_FEATURE_FLAG_ALL,
            context: ptr::null_mut(),
            filter: None,
            occluded: None,
        }
    }

    #[cfg(embree4)]
    fn query_flags(coherent: bool) -> ffi::RTCRayQueryFlags {
        if coherent { ffi::RTC_RAY_QUERY_FLAG_COHERENT } else { ffi::RTC_RAY_QUERY_FLAG_INCOHERENT }
    }

    fn ray(r: &Ray) -> ffi::RTCRay {
        ffi::RTCRay {
            org_x: r.o.x,
            org_y: r.o.y,
            org_z: r.o.z,
            tnear: r.tmin,
            dir_x: r.d.x,
            dir_y: r.d.y,
            dir_z: r.d.z,
            time: 0.0,
            tfar: r.tmax,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        }
    }

    fn rayhit(r: &Ray) -> ffi::RTCRayHit {
        ffi::RTCRayHit {
            ray: Self::ray(r),
            hit: ffi::RTCHit {
                Ng_x: 0.0,
                Ng_y: 0.0,
                Ng_z: 0.0,
                u: 0.0,
                v: 0.0,
                primID: INVALID_ID,
                geomID: INVALID_ID,
                instID: [INVALID_ID; 1],
                // Present when the Embree 4 library has instance arrays (4.3 and later by
                // default); Embree writes it on every hit.
                #[cfg(embree_inst_prim_id)]
                instPrimID: [INVALID_ID; 1],
            },
        }
    }

    fn hit(rh: &ffi::RTCRayHit) -> Option<Hit> {
        (rh.hit.geomID != INVALID_ID).then_some(Hit {
            t: rh.ray.tfar,
            geom: rh.hit.geomID,
            prim: rh.hit.primID,
            u: rh.hit.u,
            v: rh.hit.v,
        })
    }

    pub fn intersect(&self, r: &Ray) -> Option<Hit> {
        let mut rh = Self::rayhit(r);
        #[cfg(not(embree4))]
        {
            let mut ctx = Self::context(false);
            // SAFETY: the scene is committed; `ctx` and `rh` are valid, initialised structs
            // with geomID = INVALID and mask = all, as Embree requires.
            unsafe { ffi::rtcIntersect1(self.raw, &mut ctx, &mut rh) };
        }
        #[cfg(embree4)]
        {
            let mut args = Self::intersect_args(false);
            // SAFETY: the scene is committed; `args` and `rh` are valid, initialised structs
            // of the layout the library was built with (checked by `scripts/embree4.sh`
            // for the Embree 4 it assembles).
            unsafe { ffi::rtcIntersect1(self.raw, &mut rh, &mut args) };
        }
        Self::hit(&rh)
    }

    pub fn occluded(&self, r: &Ray) -> bool {
        let mut ray = Self::ray(r);
        #[cfg(not(embree4))]
        {
            let mut ctx = Self::context(false);
            // SAFETY: the scene is committed; `ctx` and `ray` are valid, initialised structs.
            unsafe { ffi::rtcOccluded1(self.raw, &mut ctx, &mut ray) };
        }
        #[cfg(embree4)]
        {
            let mut args = Self::occluded_args(false);
            // SAFETY: the scene is committed; `args` and `ray` are valid, initialised structs.
            unsafe { ffi::rtcOccluded1(self.raw, &mut ray, &mut args) };
        }
        // Embree marks an occluded ray by setting tfar to -inf.
        ray.tfar == f32::NEG_INFINITY
    }

    pub fn intersect_batch(&self, rays: &[Ray], coherent: bool, out: &mut Vec<Option<Hit>>) {
        let mut buf: Vec<ffi::RTCRayHit> = rays.iter().map(Self::rayhit).collect();
        #[cfg(not(embree4))]
        if !buf.is_empty() {
            let mut ctx = Self::context(coherent);
            // SAFETY: `buf` holds `buf.len()` initialised ray/hit structs laid out with the
            // given stride; the scene is committed.
            unsafe {
                ffi::rtcIntersect1M(self.raw, &mut ctx, buf.as_mut_ptr(), buf.len() as u32, size_of::<ffi::RTCRayHit>())
            };
        }
        // Embree 4 has no ray streams: one query per ray, with the coherence flag.
        #[cfg(embree4)]
        {
            let mut args = Self::intersect_args(coherent);
            for rh in &mut buf {
                // SAFETY: as in `intersect`; Embree does not write to the arguments.
                unsafe { ffi::rtcIntersect1(self.raw, rh, &mut args) };
            }
        }
        out.extend(buf.iter().map(Self::hit));
    }

    pub fn occluded_batch(&self, rays: &[Ray], coherent: bool, out: &mut Vec<bool>) {
        let mut buf: Vec<ffi::RTCRay> = rays.iter().map(Self::ray).collect();
        #[cfg(not(embree4))]
        if !buf.is_empty() {
            let mut ctx = Self::context(coherent);
            // SAFETY: `buf` holds `buf.len()` initialised rays with the given stride.
            unsafe {
                ffi::rtcOccluded1M(self.raw, &mut ctx, buf.as_mut_ptr(), buf.len() as u32, size_of::<ffi::RTCRay>())
            };
        }
        #[cfg(embree4)]
        {
            let mut args = Self::occluded_args(coherent);
            for r in &mut buf {
                // SAFETY: as in `occluded`.
                unsafe { ffi::rtcOccluded1(self.raw, r, &mut args) };
            }
        }
        out.extend(buf.iter().map(|r| r.tfar == f32::NEG_INFINITY));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_configuration_joins_environment_and_option() {
        assert_eq!(config_string(None, None).unwrap(), "verbose=0");
        assert_eq!(config_string(Some(" "), Some("")).unwrap(), "verbose=0");
        assert_eq!(
            config_string(Some("max_isa=sse4.2"), Some("threads=1, verbose=1")).unwrap(),
            "verbose=0,max_isa=sse4.2,threads=1,verbose=1"
        );
        for isa in ISAS {
            assert!(config_string(Some(&format!("isa={isa}")), Some(&format!("max_isa={isa}"))).is_ok());
        }
        for bad in [
            "max_isa",
            "max_isa=",
            "=avx2",
            "max isa=avx2",
            "max_isa=avx2;threads=1",
            "a=b,,c=d",
            "max_isa=avx3",
            "isa=SSE4.2",
        ] {
            let e = config_string(None, Some(bad)).unwrap_err().to_string();
            assert!(e.contains("--embree-config"), "{bad}: {e}");
            let e = config_string(Some(bad), None).unwrap_err().to_string();
            assert!(e.contains(CONFIG_ENV), "{bad}: {e}");
        }
    }

    #[test]
    fn a_device_runs_with_the_kernels_of_an_older_cpu() {
        // Embree builds and traces with the SSE4.2 kernels (what `max_isa=` selects is shown
        // by `tests/cli.rs`, from Embree's own report).
        let device = Device::new(Some("max_isa=sse4.2")).unwrap();
        device.check("rtcNewDevice").unwrap();
        let p = [glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y];
        let geometry = [Geometry::Triangles { positions: &p, indices: &[[0, 1, 2]] }];
        let options = BuildOptions { embree_config: Some("max_isa=sse4.2".into()), ..BuildOptions::default() };
        let scene = EmbreeScene::build(&geometry, &[], &options).unwrap();
        let hit = scene.intersect(&Ray::new(glam::Vec3::new(0.25, 0.25, 1.0), -glam::Vec3::Z)).unwrap();
        assert_eq!((hit.geom, hit.prim), (0, 0));
        assert!((hit.t - 1.0).abs() < 1e-6 && (hit.u - 0.25).abs() < 1e-6 && (hit.v - 0.25).abs() < 1e-6);
    }
}
