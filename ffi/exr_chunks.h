/*
 * C ABI over OpenEXR's core library (cpp/exr_chunks.cpp): a tiled EXR's tiles encoded apart
 * from its file, and written into it as they are. The thread (or rank) that renders a tile
 * compresses it; whoever holds the file only appends the bytes. Every function returns 0 on
 * success, or non-zero with a one-line, NUL-terminated message in err[0..err_len).
 */
#ifndef ICR_EXR_CHUNKS_H
#define ICR_EXR_CHUNKS_H
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A channel of the file: its name, and whether it is stored as half (else 32-bit float). */
typedef struct icr_exr_channel {
    const char *name;
    int32_t half;
} icr_exr_channel;

/*
 * The file's layout: a data window of width x height pixels whose top left pixel is (x, y) of
 * a display window full_width x full_height from (0, 0); its channels (interleaved in that
 * order in the pixels handed to the encoder); OpenEXR's codec by name (zip, piz, dwaa, none,
 * ...; NULL or empty: zip); tiles of tile_width x tile_height, in random order.
 */
typedef struct icr_exr_tiling {
    uint32_t width;
    uint32_t height;
    int32_t x;
    int32_t y;
    uint32_t full_width;
    uint32_t full_height;
    const icr_exr_channel *channels;
    size_t channel_count;
    const char *compression;
    uint32_t tile_width;
    uint32_t tile_height;
} icr_exr_tiling;

/* Receives a tile's encoded bytes (valid only during the call). */
typedef void (*icr_chunk_out)(void *context, const uint8_t *bytes, size_t len);

/*
 * Encodes tiles of a file laid out as `tiling`, from any thread at once. A tile is given by its
 * column and row in the tile grid, as interleaved floats (row by row, every channel in order;
 * the tile's rows are cut at the window's right and bottom edges).
 */
typedef struct icr_tile_encoder icr_tile_encoder;
icr_tile_encoder *icr_tile_encoder_new(const icr_exr_tiling *tiling, char *err, size_t err_len);
int icr_tile_encode(icr_tile_encoder *encoder, uint32_t tile_x, uint32_t tile_y, const float *pixels,
                    size_t value_count, icr_chunk_out out, void *context, char *err, size_t err_len);
void icr_tile_encoder_free(icr_tile_encoder *encoder);

/*
 * The file at `path` (truncated) laid out as `tiling`, with header_room bytes kept in its
 * header (attribute "icrender/reserved") for what is known only at the end. Tiles' encoded
 * bytes are written in any order, from any thread (one at a time inside); end writes the chunk
 * offsets and frees it (every tile must have been written); close abandons it.
 */
typedef struct icr_chunk_file icr_chunk_file;
icr_chunk_file *icr_chunk_file_open(const char *path, const icr_exr_tiling *tiling, size_t header_room, char *err,
                                    size_t err_len);
int icr_chunk_file_write(icr_chunk_file *file, uint32_t tile_x, uint32_t tile_y, const uint8_t *bytes, size_t len,
                         char *err, size_t err_len);
int icr_chunk_file_end(icr_chunk_file *file, char *err, size_t err_len);
void icr_chunk_file_close(icr_chunk_file *file);

#ifdef __cplusplus
}
#endif
#endif
