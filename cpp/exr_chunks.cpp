// A tiled EXR's tiles encoded apart from its file (implements ffi/exr_chunks.h on OpenEXR's
// core library). OpenImageIO and OpenEXR's C++ files compress a tile inside the call that
// writes it, so whoever holds the file also pays for every tile's compression: under mpirun the
// master compressed the whole frame on one core. Here the renderer encodes, and the file only
// takes bytes.

#include "../ffi/exr_chunks.h"

#include <openexr.h>

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstring>
#include <mutex>
#include <new>
#include <string>
#include <vector>

namespace {

constexpr const char *kReserved = "icrender/reserved";

int fail(char *err, size_t err_len, const std::string &msg) {
    if (err && err_len) {
        std::string line = msg.empty() ? "unknown error" : msg;
        std::replace(line.begin(), line.end(), '\n', ' ');
        size_t n = std::min(line.size(), err_len - 1);
        while (n > 0 && n < line.size() && (static_cast<unsigned char>(line[n]) & 0xC0) == 0x80) --n;
        std::memcpy(err, line.data(), n);
        err[n] = '\0';
    }
    return 1;
}

void clear(char *err, size_t err_len) {
    if (err && err_len) err[0] = '\0';
}

// The core library reports an error's text through a callback on the failing thread: kept here
// for the call that failed to return.
thread_local std::string last_message;

void keep_message(exr_const_context_t, exr_result_t, const char *msg) { last_message = msg ? msg : ""; }

std::string explain(exr_result_t code) {
    std::string text = last_message.empty() ? exr_get_default_error_message(code) : last_message;
    last_message.clear();
    return text;
}

bool codec(const char *name, exr_compression_t *out) {
    static const struct {
        const char *name;
        exr_compression_t codec;
    } known[] = {{"none", EXR_COMPRESSION_NONE}, {"rle", EXR_COMPRESSION_RLE},     {"zips", EXR_COMPRESSION_ZIPS},
                 {"zip", EXR_COMPRESSION_ZIP},   {"piz", EXR_COMPRESSION_PIZ},     {"pxr24", EXR_COMPRESSION_PXR24},
                 {"b44", EXR_COMPRESSION_B44},   {"b44a", EXR_COMPRESSION_B44A},   {"dwaa", EXR_COMPRESSION_DWAA},
                 {"dwab", EXR_COMPRESSION_DWAB}};
    const std::string wanted = name && *name ? name : "zip";
    for (const auto &k : known)
        if (wanted == k.name) return *out = k.codec, true;
    return false;
}

// Why `tiling` cannot make a file, or empty.
std::string check(const icr_exr_tiling *t) {
    if (!t) return "no layout";
    if (t->width == 0 || t->height == 0 || t->width > uint32_t(INT_MAX) || t->height > uint32_t(INT_MAX))
        return "invalid image size " + std::to_string(t->width) + "x" + std::to_string(t->height);
    if (t->x < 0 || t->y < 0 || t->full_width > uint32_t(INT_MAX) || t->full_height > uint32_t(INT_MAX) ||
        uint64_t(t->x) + t->width > t->full_width || uint64_t(t->y) + t->height > t->full_height)
        return "the data window does not lie inside the display window";
    if (t->tile_width == 0 || t->tile_height == 0 || t->tile_width > 4096 || t->tile_height > 4096)
        return "invalid tile size";
    if (!t->channels || t->channel_count == 0) return "no channels to write";
    if (t->channel_count > 4096) return "too many channels";
    for (size_t c = 0; c < t->channel_count; ++c) {
        if (!t->channels[c].name || !*t->channels[c].name) return "channel " + std::to_string(c) + " has no name";
        for (size_t d = 0; d < c; ++d)
            if (std::strcmp(t->channels[c].name, t->channels[d].name) == 0)
                return std::string("duplicate channel name ") + t->channels[c].name;
    }
    exr_compression_t unused;
    if (!codec(t->compression, &unused)) return std::string("unknown compression ") + t->compression;
    return "";
}

// Declares the one tiled part of `tiling` in a context opened for writing, with `room` bytes of
// spaces kept in the header; then writes the header.
exr_result_t declare(exr_context_t ctxt, const icr_exr_tiling *t, size_t room) {
    int part = 0;
    exr_result_t rv = exr_add_part(ctxt, nullptr, EXR_STORAGE_TILED, &part);
    exr_compression_t comp = EXR_COMPRESSION_ZIP;
    codec(t->compression, &comp);
    const exr_attr_box2i_t display = {{0, 0}, {int32_t(t->full_width) - 1, int32_t(t->full_height) - 1}};
    const exr_attr_box2i_t data = {{t->x, t->y}, {t->x + int32_t(t->width) - 1, t->y + int32_t(t->height) - 1}};
    const exr_attr_v2f_t centre = {0.0f, 0.0f};
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_initialize_required_attr(ctxt, part, &display, &data, 1.0f, &centre, 1.0f, EXR_LINEORDER_RANDOM_Y,
                                          comp);
    for (size_t c = 0; rv == EXR_ERR_SUCCESS && c < t->channel_count; ++c)
        rv = exr_add_channel(ctxt, part, t->channels[c].name, t->channels[c].half ? EXR_PIXEL_HALF : EXR_PIXEL_FLOAT,
                             EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_set_tile_descriptor(ctxt, part, t->tile_width, t->tile_height, EXR_TILE_ONE_LEVEL,
                                     EXR_TILE_ROUND_DOWN);
    if (rv == EXR_ERR_SUCCESS && room > 0) {
        const std::string spaces(room, ' ');
        rv = exr_attr_set_string(ctxt, part, kReserved, spaces.c_str());
    }
    if (rv == EXR_ERR_SUCCESS) rv = exr_write_header(ctxt);
    return rv;
}

int64_t discard(exr_const_context_t, void *, const void *, uint64_t size, uint64_t, exr_stream_error_func_ptr_t) {
    return int64_t(size);
}

int64_t write_at(exr_const_context_t ctxt, void *user, const void *buffer, uint64_t size, uint64_t offset,
                 exr_stream_error_func_ptr_t error) {
    const int fd = *static_cast<int *>(user);
    const char *bytes = static_cast<const char *>(buffer);
    uint64_t done = 0;
    while (done < size) {
        const ssize_t n = pwrite(fd, bytes + done, size - done, off_t(offset + done));
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            error(ctxt, EXR_ERR_WRITE_IO, "%s", std::strerror(n < 0 ? errno : ENOSPC));
            return -1;
        }
        done += uint64_t(n);
    }
    return int64_t(done);
}

exr_context_initializer_t initializer(exr_write_func_ptr_t write, void *user) {
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = keep_message;
    init.write_fn = write;
    init.user_data = user;
    return init;
}

// A tile's chunk goes to the caller instead of a file.
struct Capture {
    icr_chunk_out out;
    void *context;
};

exr_result_t hand_over(exr_encode_pipeline_t *encode) {
    const Capture *capture = static_cast<const Capture *>(encode->encoding_user_data);
    capture->out(capture->context, static_cast<const uint8_t *>(encode->compressed_buffer),
                 size_t(encode->compressed_bytes));
    return EXR_ERR_SUCCESS;
}

}  // namespace

struct icr_tile_encoder {
    exr_context_t ctxt = nullptr;
    std::vector<std::string> names;
    uint32_t width = 0, height = 0, tile_width = 0, tile_height = 0;
    ~icr_tile_encoder() {
        if (ctxt) exr_finish(&ctxt);
    }
};

extern "C" icr_tile_encoder *icr_tile_encoder_new(const icr_exr_tiling *tiling, char *err, size_t err_len) {
    clear(err, err_len);
    try {
        const std::string bad = check(tiling);
        if (!bad.empty()) return fail(err, err_len, bad), nullptr;
        auto encoder = new icr_tile_encoder();
        // A context whose file is nowhere: it holds the part's layout, which encoding needs.
        const exr_context_initializer_t init = initializer(discard, nullptr);
        exr_result_t rv = exr_start_write(&encoder->ctxt, "tile encoder", EXR_WRITE_FILE_DIRECTLY, &init);
        if (rv == EXR_ERR_SUCCESS) rv = declare(encoder->ctxt, tiling, 0);
        if (rv != EXR_ERR_SUCCESS) {
            fail(err, err_len, "EXR tile encoder: " + explain(rv));
            delete encoder;
            return nullptr;
        }
        for (size_t c = 0; c < tiling->channel_count; ++c) encoder->names.emplace_back(tiling->channels[c].name);
        encoder->width = tiling->width;
        encoder->height = tiling->height;
        encoder->tile_width = tiling->tile_width;
        encoder->tile_height = tiling->tile_height;
        // A library may know a codec it cannot encode (OpenEXR 3.1's core library has no DWA
        // encoder): the first tile, of zeros, says so now rather than in the middle of a render.
        const size_t w = std::min(tiling->tile_width, tiling->width), h = std::min(tiling->tile_height, tiling->height);
        const std::vector<float> zeros(w * h * tiling->channel_count, 0.0f);
        auto ignore = [](void *, const uint8_t *, size_t) {};
        if (icr_tile_encode(encoder, 0, 0, zeros.data(), zeros.size(), ignore, nullptr, err, err_len) != 0) {
            delete encoder;
            return nullptr;
        }
        return encoder;
    } catch (const std::bad_alloc &) {
        return fail(err, err_len, "out of memory"), nullptr;
    }
}

extern "C" int icr_tile_encode(icr_tile_encoder *encoder, uint32_t tile_x, uint32_t tile_y, const float *pixels,
                               size_t value_count, icr_chunk_out out, void *context, char *err, size_t err_len) {
    clear(err, err_len);
    if (!encoder || !encoder->ctxt || !pixels || !out) return fail(err, err_len, "EXR tile encoder: nothing to encode");
    const uint64_t x0 = uint64_t(tile_x) * encoder->tile_width, y0 = uint64_t(tile_y) * encoder->tile_height;
    if (x0 >= encoder->width || y0 >= encoder->height) return fail(err, err_len, "EXR tile encoder: no such tile");
    const uint64_t w = std::min<uint64_t>(encoder->tile_width, encoder->width - x0);
    const uint64_t h = std::min<uint64_t>(encoder->tile_height, encoder->height - y0);
    const size_t n = encoder->names.size();
    if (value_count != w * h * n) return fail(err, err_len, "EXR tile encoder: the tile has the wrong size");

    exr_chunk_info_t chunk;
    exr_result_t rv = exr_write_tile_chunk_info(encoder->ctxt, 0, int(tile_x), int(tile_y), 0, 0, &chunk);
    exr_encode_pipeline_t encode = {};
    bool initialised = false;
    if (rv == EXR_ERR_SUCCESS) {
        rv = exr_encoding_initialize(encoder->ctxt, 0, &chunk, &encode);
        initialised = rv == EXR_ERR_SUCCESS;
    }
    Capture capture{out, context};
    if (rv == EXR_ERR_SUCCESS) {
        // The file sorts its channels by name; each finds its place among the interleaved values.
        for (int c = 0; c < encode.channel_count; ++c) {
            exr_coding_channel_info_t &channel = encode.channels[c];
            const auto at = std::find(encoder->names.begin(), encoder->names.end(), channel.channel_name);
            if (at == encoder->names.end()) {
                rv = EXR_ERR_INVALID_ARGUMENT;
                last_message = std::string("no values for channel ") + channel.channel_name;
                break;
            }
            channel.encode_from_ptr = reinterpret_cast<const uint8_t *>(pixels + (at - encoder->names.begin()));
            channel.user_pixel_stride = int32_t(n * sizeof(float));
            channel.user_line_stride = int32_t(w * n * sizeof(float));
            channel.user_data_type = EXR_PIXEL_FLOAT;
            channel.user_bytes_per_element = sizeof(float);
        }
    }
    if (rv == EXR_ERR_SUCCESS) rv = exr_encoding_choose_default_routines(encoder->ctxt, 0, &encode);
    if (rv == EXR_ERR_SUCCESS) {
        // Neither the wait for this chunk's turn in the file nor the write: the bytes go to `out`.
        encode.yield_until_ready_fn = nullptr;
        encode.write_fn = hand_over;
        encode.encoding_user_data = &capture;
        rv = exr_encoding_run(encoder->ctxt, 0, &encode);
    }
    if (initialised) exr_encoding_destroy(encoder->ctxt, &encode);
    if (rv != EXR_ERR_SUCCESS) return fail(err, err_len, "EXR tile encoding failed: " + explain(rv));
    return 0;
}

extern "C" void icr_tile_encoder_free(icr_tile_encoder *encoder) { delete encoder; }

struct icr_chunk_file {
    exr_context_t ctxt = nullptr;
    int fd = -1;
    std::mutex lock;
    bool broken = false;
};

extern "C" icr_chunk_file *icr_chunk_file_open(const char *path, const icr_exr_tiling *tiling, size_t header_room,
                                               char *err, size_t err_len) {
    clear(err, err_len);
    try {
        if (!path || !*path) return fail(err, err_len, "empty path"), nullptr;
        const std::string bad = check(tiling);
        if (!bad.empty()) return fail(err, err_len, bad), nullptr;
        auto file = new icr_chunk_file();
        file->fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
        if (file->fd < 0) {
            fail(err, err_len, std::string("cannot open for writing: ") + std::strerror(errno));
            delete file;
            return nullptr;
        }
        const exr_context_initializer_t init = initializer(write_at, &file->fd);
        exr_result_t rv = exr_start_write(&file->ctxt, path, EXR_WRITE_FILE_DIRECTLY, &init);
        if (rv == EXR_ERR_SUCCESS) rv = declare(file->ctxt, tiling, header_room);
        if (rv != EXR_ERR_SUCCESS) {
            fail(err, err_len, "cannot write the EXR header: " + explain(rv));
            icr_chunk_file_close(file);
            return nullptr;
        }
        return file;
    } catch (const std::bad_alloc &) {
        return fail(err, err_len, "out of memory"), nullptr;
    }
}

extern "C" int icr_chunk_file_write(icr_chunk_file *file, uint32_t tile_x, uint32_t tile_y, const uint8_t *bytes,
                                    size_t len, char *err, size_t err_len) {
    clear(err, err_len);
    if (!file || !file->ctxt) return fail(err, err_len, "the file is closed");
    std::lock_guard<std::mutex> held(file->lock);
    if (file->broken) return fail(err, err_len, "an earlier write to the file failed");
    const exr_result_t rv = exr_write_tile_chunk(file->ctxt, 0, int(tile_x), int(tile_y), 0, 0, bytes, len);
    if (rv != EXR_ERR_SUCCESS) {
        file->broken = true;
        return fail(err, err_len, "write failed: " + explain(rv));
    }
    return 0;
}

extern "C" int icr_chunk_file_end(icr_chunk_file *file, char *err, size_t err_len) {
    clear(err, err_len);
    if (!file || !file->ctxt) return fail(err, err_len, "the file is closed");
    std::string problem;
    if (file->broken) {
        problem = "an earlier write to the file failed";
    } else {
        // The offsets were written with the last tile; a file short of tiles is not finished.
        exr_result_t rv = exr_finish(&file->ctxt);
        if (rv != EXR_ERR_SUCCESS) problem = "close failed: " + explain(rv);
        file->ctxt = nullptr;
    }
    icr_chunk_file_close(file);
    return problem.empty() ? 0 : fail(err, err_len, problem);
}

extern "C" void icr_chunk_file_close(icr_chunk_file *file) {
    if (!file) return;
    if (file->ctxt) exr_finish(&file->ctxt);
    if (file->fd >= 0) close(file->fd);
    delete file;
}
