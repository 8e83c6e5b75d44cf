/* Frames as .npy files for the C API's tests: float64, shape (F, N, C), little-endian, C order.
 * Written with the header pmsc writes (pmsc/NpyIO.cpp: NumPy's layout, data on a 64-byte
 * boundary), so a file written here and one written by `pmsc replay --out` compare byte for byte. */
#ifndef PMSC_TESTS_CAPI_NPY_FRAMES_H
#define PMSC_TESTS_CAPI_NPY_FRAMES_H

#include <stddef.h>
#include <stdio.h>

/** F frames of N points of C channels: frame f, point p, channel c at values[(f*N + p)*C + c]. */
typedef struct npy_frames {
    size_t frames, points, channels;
    double* values;
} npy_frames;

/** Reads a float64 (F, N, C) C-order .npy file. Returns 0, or -1 with a message in error. */
int npy_frames_read(const char* path, npy_frames* out, char* error, size_t error_size);

void npy_frames_free(npy_frames* frames);

/** Opens `path` for writing `frames` frames of points x channels float64 values and writes the
 *  header. Returns the file, or NULL with a message in error. */
FILE* npy_frames_create(const char* path, size_t frames, size_t points, size_t channels, char* error,
                        size_t error_size);

/** Appends `count` values, little-endian. Returns 0, or -1. */
int npy_frames_write(FILE* file, const double* values, size_t count);

#endif
