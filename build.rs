//! Binds the system Embree with bindgen.
//!
//! Search order for the headers: `$EMBREE_DIR/include`, then the standard include paths
//! (`/usr/include`, `/usr/local/include`). Embree 4 headers, if present, are preferred;
//! the choice is passed to the crate as `cfg(embree4)`. The library is linked as
//! `embree4` or `embree3`, from `$EMBREE_DIR/lib` when given, else from the default
//! linker paths (Debian's `libembree-dev` has no pkg-config file). With `$EMBREE_DIR` the
//! binaries get an rpath to its library folder.
//!
//! With `--features oiio`, it also compiles the C++ side of the OpenImageIO bridge
//! (`src/ffi/oiio.cpp`, with `cxx`) against the system OpenImageIO: found by
//! pkg-config (`OpenImageIO.pc`), or under `$OIIO_DIR` (`include/`, `lib/`) when given.
//!
//! With `--features oidn` and `$OIDN_DIR` (the `oidn` crate links Open Image Denoise from
//! `$OIDN_DIR/lib`), the binaries get an rpath to that folder.

use std::env;
use std::path::{Path, PathBuf};

fn main() {
    build_oiio_bridge();
    oidn_rpath();
    println!("cargo:rerun-if-changed=wrapper.h");
    println!("cargo:rerun-if-env-changed=EMBREE_DIR");
    println!("cargo::rustc-check-cfg=cfg(embree4)");
    println!("cargo::rustc-check-cfg=cfg(embree_inst_prim_id)");

    let embree_dir = env::var_os("EMBREE_DIR").map(PathBuf::from);
    let mut include_dirs: Vec<PathBuf> = Vec::new();
    if let Some(dir) = &embree_dir {
        include_dirs.push(dir.join("include"));
    }
    include_dirs.push(PathBuf::from("/usr/local/include"));
    include_dirs.push(PathBuf::from("/usr/include"));

    let has = |major: &str| -> Option<PathBuf> {
        include_dirs.iter().find(|d| d.join(format!("embree{major}/rtcore.h")).is_file()).cloned()
    };
    let (major, include) = match (has("4"), has("3")) {
        (Some(dir), _) => ("4", dir),
        (None, Some(dir)) => ("3", dir),
        (None, None) => {
            let searched: Vec<String> = include_dirs.iter().map(|d| d.display().to_string()).collect();
            panic!(
                "Embree headers not found (looked for embree4/rtcore.h and embree3/rtcore.h in {}). \
                 Install them with `scripts/setup.sh` (Debian: `apt-get install libembree-dev`) \
                 or point EMBREE_DIR at an Embree installation.",
                searched.join(", ")
            );
        }
    };

    if let Some(dir) = &embree_dir {
        for lib in ["lib", "lib64"] {
            let p = dir.join(lib);
            if p.is_dir() {
                println!("cargo:rustc-link-search=native={}", p.display());
                // The test binaries and `pcbpt` find this Embree at run time without
                // LD_LIBRARY_PATH.
                println!("cargo:rustc-link-arg=-Wl,-rpath,{}", p.display());
            }
        }
    }
    println!("cargo:rustc-link-lib=dylib=embree{major}");
    if major == "4" {
        println!("cargo:rustc-cfg=embree4");
    }

    let mut builder = bindgen::Builder::default()
        .header("wrapper.h")
        .clang_arg(format!("-I{}", include.display()))
        .allowlist_function("rtc.*")
        .allowlist_type("RTC.*")
        .allowlist_var("RTC_.*")
        .rustified_enum("RTCError")
        .rustified_enum("RTCGeometryType")
        .rustified_enum("RTCBufferType")
        .rustified_enum("RTCFormat")
        .rustified_enum("RTCBuildQuality")
        .rustified_enum("RTCDeviceProperty")
        .bitfield_enum("RTCSceneFlags")
        .prepend_enum_name(false)
        .layout_tests(true)
        .parse_callbacks(Box::new(bindgen::CargoCallbacks::new()));
    if major == "4" {
        builder = builder.clang_arg("-DPCBPT_EMBREE4");
    }
    let bindings = builder.generate().expect("bindgen failed on wrapper.h");
    // An Embree 4 built with instance arrays (rtcore_config.h defines
    // RTC_GEOMETRY_INSTANCE_ARRAY) has an `instPrimID` stack in RTCHit, which the crate
    // must initialise.
    if bindings.to_string().contains("pub instPrimID:") {
        println!("cargo:rustc-cfg=embree_inst_prim_id");
    }
    let out = PathBuf::from(env::var("OUT_DIR").expect("OUT_DIR is set by cargo"));
    bindings.write_to_file(Path::new(&out).join("embree_bindings.rs")).expect("could not write the Embree bindings");
}

/// Compiles the OpenImageIO bridge and links OpenImageIO (`--features oiio`).
#[cfg(feature = "oiio")]
fn build_oiio_bridge() {
    for file in ["src/ffi/oiio.rs", "src/ffi/oiio.cpp", "src/ffi/oiio.h"] {
        println!("cargo:rerun-if-changed={file}");
    }
    println!("cargo:rerun-if-env-changed=OIIO_DIR");
    let mut include_dirs: Vec<PathBuf> = Vec::new();
    if let Some(dir) = env::var_os("OIIO_DIR").map(PathBuf::from) {
        include_dirs.push(dir.join("include"));
        for lib in ["lib", "lib64"] {
            let p = dir.join(lib);
            if p.is_dir() {
                println!("cargo:rustc-link-search=native={}", p.display());
            }
        }
        println!("cargo:rustc-link-lib=dylib=OpenImageIO");
        println!("cargo:rustc-link-lib=dylib=OpenImageIO_Util");
    } else {
        match pkg_config::Config::new().atleast_version("2.4").probe("OpenImageIO") {
            Ok(lib) => include_dirs.extend(lib.include_paths),
            Err(e) => panic!(
                "OpenImageIO >= 2.4 not found by pkg-config ({e}). Install it with \
                 `scripts/setup.sh --with-oiio` (Debian: `apt-get install libopenimageio-dev`) \
                 or point OIIO_DIR at an OpenImageIO installation."
            ),
        }
    }
    cxx_build::bridge("src/ffi/oiio.rs")
        .file("src/ffi/oiio.cpp")
        .includes(&include_dirs)
        .std("c++17")
        .compile("pcbpt_oiio");
}

/// Nothing to build without `--features oiio`.
#[cfg(not(feature = "oiio"))]
fn build_oiio_bridge() {}

/// With `--features oidn`, an rpath to `$OIDN_DIR/lib` (where the `oidn` crate links Open
/// Image Denoise from; `scripts/setup.sh --with-oidn` assembles it), so that `pcbpt` and the
/// tests find the library without LD_LIBRARY_PATH.
fn oidn_rpath() {
    println!("cargo:rerun-if-env-changed=OIDN_DIR");
    if env::var_os("CARGO_FEATURE_OIDN").is_none() {
        return;
    }
    if let Some(dir) = env::var_os("OIDN_DIR").filter(|d| !d.is_empty()) {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", PathBuf::from(dir).join("lib").display());
    }
}
