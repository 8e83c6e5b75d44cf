/* A small .npy reader and writer for float64 (F, N, C) frames (see npy_frames.h). */
#include "npy_frames.h"

#include <errno.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static const char kMagic[6] = {'\x93', 'N', 'U', 'M', 'P', 'Y'};

static int fail(char* error, size_t error_size, const char* path, const char* what) {
    snprintf(error, error_size, "%s: %s", path, what);
    return -1;
}

static uint64_t load_le(const unsigned char* bytes, int count) {
    uint64_t v = 0;
    for (int i = count - 1; i >= 0; --i) v = (v << 8) | bytes[i];
    return v;
}

/* The three dimensions of "'shape': (F, N, C)" in a header dictionary. */
static int parse_shape(const char* header, size_t dims[3]) {
    const char* at = strstr(header, "'shape':");
    if (at == NULL) return -1;
    at = strchr(at, '(');
    if (at == NULL) return -1;
    ++at;
    for (int d = 0; d < 3; ++d) {
        char* end = NULL;
        errno = 0;
        const unsigned long long v = strtoull(at, &end, 10);
        if (end == at || errno != 0) return -1;
        dims[d] = (size_t)v;
        at = end;
        while (*at == ' ') ++at;
        if (*at != (d < 2 ? ',' : ')')) return -1;
        ++at;
        while (*at == ' ') ++at;
    }
    return 0;
}

static int read_header(FILE* file, const char* path, npy_frames* out, char* error, size_t error_size) {
    unsigned char prefix[12];
    if (fread(prefix, 1, 10, file) != 10 || memcmp(prefix, kMagic, sizeof kMagic) != 0)
        return fail(error, error_size, path, "not a .npy file");
    size_t length_bytes = prefix[6] == 1 ? 2 : 4;
    if (length_bytes == 4 && fread(prefix + 10, 1, 2, file) != 2)
        return fail(error, error_size, path, "truncated header");
    const size_t header_length = (size_t)load_le(prefix + 8, (int)length_bytes);
    char* header = malloc(header_length + 1);
    if (header == NULL) return fail(error, error_size, path, "out of memory");
    int status = 0;
    size_t dims[3] = {0, 0, 0};
    if (fread(header, 1, header_length, file) != header_length) {
        status = fail(error, error_size, path, "truncated header");
    } else {
        header[header_length] = '\0';
        if (strstr(header, "'descr': '<f8'") == NULL)
            status = fail(error, error_size, path, "not float64 ('<f8')");
        else if (strstr(header, "'fortran_order': False") == NULL)
            status = fail(error, error_size, path, "not C order");
        else if (parse_shape(header, dims) != 0)
            status = fail(error, error_size, path, "shape is not (frames, points, channels)");
    }
    free(header);
    out->frames = dims[0];
    out->points = dims[1];
    out->channels = dims[2];
    return status;
}

int npy_frames_read(const char* path, npy_frames* out, char* error, size_t error_size) {
    memset(out, 0, sizeof *out);
    FILE* file = fopen(path, "rb");
    if (file == NULL) return fail(error, error_size, path, strerror(errno));
    int status = read_header(file, path, out, error, error_size);
    const size_t count = out->frames * out->points * out->channels;
    if (status == 0 && out->points != 0 && out->channels != 0 &&
        (out->frames > SIZE_MAX / 8 / out->points / out->channels))
        status = fail(error, error_size, path, "shape too large");
    unsigned char* bytes = status == 0 ? malloc(count * 8 + 1) : NULL;
    if (status == 0 && bytes == NULL) status = fail(error, error_size, path, "out of memory");
    if (status == 0 && fread(bytes, 8, count, file) != count)
        status = fail(error, error_size, path, "truncated data");
    if (status == 0) {
        out->values = malloc(count * sizeof(double) + 1);
        if (out->values == NULL) status = fail(error, error_size, path, "out of memory");
    }
    for (size_t i = 0; status == 0 && i < count; ++i) {
        const uint64_t bits = load_le(bytes + 8 * i, 8);
        memcpy(&out->values[i], &bits, sizeof bits);
    }
    free(bytes);
    fclose(file);
    if (status != 0) npy_frames_free(out);
    return status;
}

void npy_frames_free(npy_frames* frames) {
    free(frames->values);
    memset(frames, 0, sizeof *frames);
}

FILE* npy_frames_create(const char* path, size_t frames, size_t points, size_t channels, char* error,
                        size_t error_size) {
    char dict[256];
    const int length =
        snprintf(dict, sizeof dict, "{'descr': '<f8', 'fortran_order': False, 'shape': (%zu, %zu, %zu), }",
                 frames, points, channels);
    /* Version 1.0: magic, 2 version bytes, a 2-byte length, then the dictionary padded with spaces
     * and ended by a newline so the data start on a 64-byte boundary. */
    const size_t padded = (10 + (size_t)length + 1 + 63) / 64 * 64 - 10;
    FILE* file = fopen(path, "wb");
    if (file == NULL) {
        fail(error, error_size, path, strerror(errno));
        return NULL;
    }
    const unsigned char prefix[10] = {
        0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, (unsigned char)(padded & 0xff), (unsigned char)(padded >> 8)};
    int ok = fwrite(prefix, 1, sizeof prefix, file) == sizeof prefix &&
             fwrite(dict, 1, (size_t)length, file) == (size_t)length;
    for (size_t i = (size_t)length; ok && i + 1 < padded; ++i) ok = fputc(' ', file) != EOF;
    if (!ok || fputc('\n', file) == EOF) {
        fclose(file);
        fail(error, error_size, path, "cannot write the header");
        return NULL;
    }
    return file;
}

int npy_frames_write(FILE* file, const double* values, size_t count) {
    for (size_t i = 0; i < count; ++i) {
        uint64_t bits;
        memcpy(&bits, &values[i], sizeof bits);
        unsigned char bytes[8];
        for (int b = 0; b < 8; ++b) bytes[b] = (unsigned char)(bits >> (8 * b));
        if (fwrite(bytes, 1, 8, file) != 8) return -1;
    }
    return 0;
}
