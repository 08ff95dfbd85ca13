// OpenImageIO calls behind the `cxx` bridge of `src/ffi/oiio.rs` (declared in oiio.h).

#include "pcbpt/src/ffi/oiio.h"
#include "pcbpt/src/ffi/oiio.rs.h"

#include <OpenImageIO/imagebufalgo.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

namespace pcbpt {
namespace oiio {
namespace {

// An error message without the trailing newlines OpenImageIO leaves on some.
std::runtime_error failure(std::string msg) {
    while (!msg.empty() && (msg.back() == '\n' || msg.back() == ' ')) msg.pop_back();
    if (msg.empty()) msg = "OpenImageIO reported a failure without a message";
    return std::runtime_error(msg);
}

// Runs `f`, turning any exception that is not a std::exception into one, so that cxx can
// hand every failure to Rust as an `Err`.
template <typename F> auto guarded(F&& f) -> decltype(f()) {
    try {
        return f();
    } catch (const std::exception&) {
        throw;
    } catch (...) {
        throw std::runtime_error("OpenImageIO failed with an unknown C++ exception");
    }
}

// The channels to return: R, G, B (and A) by name where the file names them, else by
// count: 1 grey, 2 grey and alpha, 3 RGB, 4 RGBA.
std::vector<int> pick_channels(const OIIO::ImageSpec& spec) {
    const int r = spec.channelindex("R"), g = spec.channelindex("G"), b = spec.channelindex("B");
    if (r >= 0 && g >= 0 && b >= 0) {
        const int a = spec.channelindex("A");
        return a >= 0 ? std::vector<int>{r, g, b, a} : std::vector<int>{r, g, b};
    }
    const int n = spec.nchannels;
    if (n >= 1 && n <= 4) {
        std::vector<int> all(n);
        for (int c = 0; c < n; ++c) all[c] = c;
        return all;
    }
    std::string names;
    for (const auto& name : spec.channelnames) names += (names.empty() ? "" : ", ") + name;
    throw failure("the image has " + std::to_string(n) + " channels (" + names +
                  "); expected 1 to 4 channels, or channels named R, G and B");
}

// The type pixels are returned in: 8-bit integers as 8 bits, wider integers as 16 bits,
// half, float and double as float.
OIIO::TypeDesc returned_type(OIIO::TypeDesc stored) {
    switch (stored.basetype) {
    case OIIO::TypeDesc::UINT8:
    case OIIO::TypeDesc::INT8: return OIIO::TypeDesc::UINT8;
    case OIIO::TypeDesc::HALF:
    case OIIO::TypeDesc::FLOAT:
    case OIIO::TypeDesc::DOUBLE: return OIIO::TypeDesc::FLOAT;
    default: return OIIO::TypeDesc::UINT16;
    }
}

template <typename T>
void write_pixels(rust::Str path, rust::Str format, std::uint32_t width, std::uint32_t height, std::uint32_t channels,
                  rust::Slice<const T> data, OIIO::TypeDesc type) {
    guarded([&] {
        if (data.size() != std::size_t(width) * height * channels)
            throw failure("the pixel buffer does not match the image size");
        auto out = OIIO::ImageOutput::create(std::string(format));
        if (!out) throw failure(OIIO::geterror());
        OIIO::ImageSpec spec(int(width), int(height), int(channels), type);
        spec.attribute("oiio:ColorSpace", type == OIIO::TypeDesc::UINT8 ? "sRGB" : "Linear");
        const std::string file(path);
        if (!out->open(file, spec)) throw failure(out->geterror());
        const bool written = out->write_image(type, data.data());
        const bool closed = out->close();
        if (!written || !closed) throw failure(out->geterror());
    });
}

}  // namespace

Input::Input(std::unique_ptr<OIIO::ImageInput> in, std::vector<int> channels, OIIO::TypeDesc type)
    : in_(std::move(in)), channels_(std::move(channels)), type_(type) {
    // Count the MIP levels by visiting them (at most 64: sizes up to 2^63), then return to
    // the full-resolution level.
    while (mip_levels_ < 64 && in_->seek_subimage(0, int(mip_levels_))) ++mip_levels_;
    in_->geterror();  // seeking past the last level may leave an error message
    if (!in_->seek_subimage(0, 0)) throw failure(in_->geterror());
}

Info Input::info() const {
    const OIIO::ImageSpec& spec = in_->spec();
    Info info;
    info.width = std::uint32_t(spec.width);
    info.height = std::uint32_t(spec.height);
    info.channels = std::uint32_t(channels_.size());
    info.bits = type_ == OIIO::TypeDesc::UINT8 ? 8 : type_ == OIIO::TypeDesc::UINT16 ? 16 : 32;
    info.format = rust::String(in_->format_name());
    info.tile_width = std::uint32_t(std::max(spec.tile_width, 0));
    info.tile_height = std::uint32_t(std::max(spec.tile_height, 0));
    info.mip_levels = mip_levels_;
    return info;
}

template <typename T> void Input::read(rust::Slice<T> out, OIIO::TypeDesc type) {
    guarded([&] {
        const OIIO::ImageSpec& spec = in_->spec();
        const std::size_t pixels = std::size_t(spec.width) * std::size_t(spec.height);
        const std::size_t n = channels_.size();
        if (type != type_ || out.size() != pixels * n)
            throw failure("the pixel buffer does not match the image's size or type");
        const int begin = *std::min_element(channels_.begin(), channels_.end());
        const int end = *std::max_element(channels_.begin(), channels_.end()) + 1;
        bool in_order = std::size_t(end - begin) == n;
        for (std::size_t c = 0; c < n; ++c) in_order = in_order && channels_[c] == begin + int(c);
        // Subimage 0, MIP level 0: the full-resolution image.
        if (in_order) {
            if (!in_->read_image(0, 0, begin, end, type, out.data())) throw failure(in_->geterror());
            return;
        }
        const std::size_t span = std::size_t(end - begin);
        std::vector<T> all(pixels * span);
        if (!in_->read_image(0, 0, begin, end, type, all.data())) throw failure(in_->geterror());
        for (std::size_t p = 0; p < pixels; ++p)
            for (std::size_t c = 0; c < n; ++c) out[p * n + c] = all[p * span + std::size_t(channels_[c] - begin)];
    });
}

void Input::read_u8(rust::Slice<std::uint8_t> out) { read(out, OIIO::TypeDesc::UINT8); }
void Input::read_u16(rust::Slice<std::uint16_t> out) { read(out, OIIO::TypeDesc::UINT16); }
void Input::read_f32(rust::Slice<float> out) { read(out, OIIO::TypeDesc::FLOAT); }

std::unique_ptr<Input> open(rust::Str path) {
    return guarded([&] {
        // Straight (unassociated) alpha as stored, like the `image` crate: colour is never
        // multiplied by alpha.
        OIIO::ImageSpec config;
        config.attribute("oiio:UnassociatedAlpha", 1);
        auto in = OIIO::ImageInput::open(std::string(path), &config);
        if (!in) throw failure(OIIO::geterror());
        const OIIO::ImageSpec& spec = in->spec();
        if (spec.width <= 0 || spec.height <= 0) throw failure("the image has no pixels");
        if (spec.depth > 1) throw failure("the image is a volume (depth " + std::to_string(spec.depth) + ")");
        auto channels = pick_channels(spec);
        const auto type = returned_type(spec.format);
        return std::make_unique<Input>(std::move(in), std::move(channels), type);
    });
}

void write_u8(rust::Str path, rust::Str format, std::uint32_t width, std::uint32_t height, std::uint32_t channels,
              rust::Slice<const std::uint8_t> data) {
    write_pixels(path, format, width, height, channels, data, OIIO::TypeDesc::UINT8);
}

void write_f32(rust::Str path, rust::Str format, std::uint32_t width, std::uint32_t height, std::uint32_t channels,
               rust::Slice<const float> data) {
    write_pixels(path, format, width, height, channels, data, OIIO::TypeDesc::FLOAT);
}

void make_texture(rust::Str src, rust::Str dst) {
    guarded([&] {
        OIIO::ImageSpec config;
        // The output's format is named, not taken from `dst`'s extension: `dst` is a
        // temporary name.
        config.attribute("maketx:fileformatname", "tiff");
        if (!OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, std::string(src), std::string(dst),
                                              config))
            throw failure(OIIO::geterror());
    });
}

}  // namespace oiio
}  // namespace pcbpt
