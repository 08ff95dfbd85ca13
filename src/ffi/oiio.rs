//! The `cxx` bridge to the system OpenImageIO (`--features oiio`): the declarations of the
//! C++ functions in `oiio.h`/`oiio.cpp` beside this file. The safe reading and writing
//! built on them is `image_io::oiio`.

// SAFETY: the `unsafe extern "C++"` block asserts that these declarations match the C++
// ones in `oiio.h`; cxx's generated C++ checks each signature against them at compile
// time. Slices are passed with their lengths (the C++ side checks them against the image
// size before writing or reading), C++ exceptions become `Err`, and the generated Rust
// wrappers are safe functions.
#[cxx::bridge(namespace = "pcbpt::oiio")]
pub mod bridge {
    /// What OpenImageIO finds in a file, and what `image_io::oiio::read` returns of it.
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub struct Info {
        /// Full-resolution size of the first subimage.
        pub width: u32,
        pub height: u32,
        /// Channels returned: 1 grey, 2 grey and alpha, 3 RGB, 4 RGBA.
        pub channels: u32,
        /// Bits per returned channel: 8 and 16 unsigned integers, 32 float.
        pub bits: u32,
        /// OpenImageIO's name of the file's format (`tiff`, `openexr`, `hdr`, …).
        pub format: String,
        /// Tile size; 0 for an image stored in scanlines.
        pub tile_width: u32,
        pub tile_height: u32,
        /// MIP levels of the first subimage (1 when it is not mip-mapped).
        pub mip_levels: u32,
    }

    unsafe extern "C++" {
        include!("pcbpt/src/ffi/oiio.h");

        /// An open image file (subimage 0, MIP level 0).
        type Input;

        fn open(path: &str) -> Result<UniquePtr<Input>>;
        fn info(self: &Input) -> Info;
        fn read_u8(self: Pin<&mut Input>, out: &mut [u8]) -> Result<()>;
        fn read_u16(self: Pin<&mut Input>, out: &mut [u16]) -> Result<()>;
        fn read_f32(self: Pin<&mut Input>, out: &mut [f32]) -> Result<()>;
        fn write_u8(path: &str, format: &str, width: u32, height: u32, channels: u32, data: &[u8]) -> Result<()>;
        fn write_f32(path: &str, format: &str, width: u32, height: u32, channels: u32, data: &[f32]) -> Result<()>;
        fn make_texture(src: &str, dst: &str) -> Result<()>;
    }
}

pub use bridge::*;
