// The C++ side of the OpenImageIO bridge (`src/ffi/oiio.rs`): opens any image
// OpenImageIO reads and copies its full-resolution pixels into Rust buffers, writes images
// through OpenImageIO's writers, and makes tiled, mip-mapped TIFF textures. Every function
// reports failure by throwing std::runtime_error, which cxx turns into a Rust `Err`; no
// other exception leaves these functions.
#pragma once

#include "rust/cxx.h"

#include <OpenImageIO/imageio.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace pcbpt {
namespace oiio {

struct Info;

// An open image file: subimage 0 at MIP level 0 (the full resolution), with the channels
// that will be returned (grey, grey and alpha, RGB or RGBA) chosen.
class Input {
public:
    Input(std::unique_ptr<OIIO::ImageInput> in, std::vector<int> channels, OIIO::TypeDesc type);
    Info info() const;
    void read_u8(rust::Slice<std::uint8_t> out);
    void read_u16(rust::Slice<std::uint16_t> out);
    void read_f32(rust::Slice<float> out);

private:
    template <typename T> void read(rust::Slice<T> out, OIIO::TypeDesc type);

    std::unique_ptr<OIIO::ImageInput> in_;
    std::vector<int> channels_;
    OIIO::TypeDesc type_;
    std::uint32_t mip_levels_ = 0;
};

std::unique_ptr<Input> open(rust::Str path);
void write_u8(rust::Str path, rust::Str format, std::uint32_t width, std::uint32_t height, std::uint32_t channels,
              rust::Slice<const std::uint8_t> data);
void write_f32(rust::Str path, rust::Str format, std::uint32_t width, std::uint32_t height, std::uint32_t channels,
               rust::Slice<const float> data);
void make_texture(rust::Str src, rust::Str dst);

}  // namespace oiio
}  // namespace pcbpt
