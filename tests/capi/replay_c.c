/* Replays recorded frames through the C API as `pmsc replay --out` does, and writes the same file.
 *
 *   pmsc_capi_replay MODEL.pmsc FRAMES.npy OUT.npy [EPS_MIN EPS_MAX]
 *
 * For every frame: the key points' recorded values, their projection, the key error, the
 * soft-cache decision and the reconstruction of every point; a hit is checked at the model's
 * sentinels (their recorded values), and one that fails the check is a blend of weight 0. The
 * output is the reconstruction for a hit, the recorded frame for a miss and their blend
 * (pmsc_multiplier_blend) otherwise. Prints the state of
 * each frame, one per line ("hit", "blend", "miss"). Exit code 0, or 1 with one line on stderr. */
#include <pmsc/pmsc.h>

#include "npy_frames.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Reports a failed call by its status and the library's message, and leaves. */
#define CHECK(call)                                                                               \
    do {                                                                                          \
        const pmsc_status status_ = (call);                                                       \
        if (status_ != PMSC_OK) {                                                                 \
            fprintf(stderr, "replay_c: %s (%s)\n", pmsc_last_error(), pmsc_status_name(status_)); \
            exit(1);                                                                              \
        }                                                                                         \
    } while (0)

static void* allocate(size_t count, size_t size) {
    void* p = calloc(count == 0 ? 1 : count, size);
    if (p == NULL) {
        fprintf(stderr, "replay_c: out of memory\n");
        exit(1);
    }
    return p;
}

/* What one frame needs: the model's sizes and per-frame buffers. */
typedef struct replay_buffers {
    size_t n, c, k, s, coord_count;
    int64_t *key_points, *sentinels;
    double *keys, *sentinel_values, *coords, *pm, *out;
} replay_buffers;

static replay_buffers make_buffers(const pmsc_multiplier* multiplier) {
    replay_buffers b;
    const pmsc_model* model = NULL;
    CHECK(pmsc_multiplier_model(multiplier, &model));
    CHECK(pmsc_model_point_count(model, &b.n));
    CHECK(pmsc_model_channel_count(model, &b.c));
    CHECK(pmsc_model_key_count(model, &b.k));
    CHECK(pmsc_model_coord_count(model, &b.coord_count));
    b.key_points = allocate(b.k, sizeof *b.key_points);
    CHECK(pmsc_model_key_points(model, b.key_points, b.k));
    CHECK(pmsc_model_sentinel_count(model, &b.s));
    b.sentinels = allocate(b.s, sizeof *b.sentinels);
    if (b.s > 0) CHECK(pmsc_model_sentinels(model, b.sentinels, b.s));
    b.sentinel_values = allocate(b.s * b.c, sizeof(double));
    b.keys = allocate(b.k * b.c, sizeof(double));
    b.coords = allocate(b.coord_count, sizeof(double));
    b.pm = allocate(b.n * b.c, sizeof(double));
    b.out = allocate(b.n * b.c, sizeof(double));
    return b;
}

static void free_buffers(replay_buffers* b) {
    free(b->key_points);
    free(b->sentinels);
    free(b->sentinel_values);
    free(b->keys);
    free(b->coords);
    free(b->pm);
    free(b->out);
}

/* One frame through the soft cache: its state, and the soft-cached values in b->out. */
static pmsc_cache_state replay_frame(const pmsc_multiplier* multiplier, replay_buffers* b,
                                     const double* recorded) {
    const size_t values = b->n * b->c;
    for (size_t i = 0; i < b->k; ++i)
        for (size_t ch = 0; ch < b->c; ++ch)
            b->keys[i * b->c + ch] = recorded[(size_t)b->key_points[i] * b->c + ch];
    double key_error = 0;
    pmsc_decision decision;
    CHECK(pmsc_multiplier_project(multiplier, b->keys, b->k * b->c, b->coords, b->coord_count));
    CHECK(pmsc_multiplier_key_error(multiplier, b->keys, b->k * b->c, b->coords, b->coord_count, &key_error));
    CHECK(pmsc_multiplier_decide(multiplier, key_error, &decision));
    CHECK(pmsc_multiplier_reconstruct(multiplier, b->coords, b->coord_count, b->pm, values));
    if (decision.state == PMSC_HIT && b->s > 0) {
        for (size_t i = 0; i < b->s; ++i)
            for (size_t ch = 0; ch < b->c; ++ch)
                b->sentinel_values[i * b->c + ch] = recorded[(size_t)b->sentinels[i] * b->c + ch];
        int stands = 0;
        CHECK(pmsc_multiplier_check_sentinels(multiplier, b->coords, b->coord_count, b->sentinel_values,
                                              b->s * b->c, &stands));
        if (!stands) {
            decision.state = PMSC_BLEND;
            decision.weight = 0.0;
        }
    }
    switch (decision.state) {
        case PMSC_HIT:
            memcpy(b->out, b->pm, values * sizeof(double));
            break;
        case PMSC_MISS:
            memcpy(b->out, recorded, values * sizeof(double));
            break;
        default:
            CHECK(pmsc_multiplier_blend(multiplier, decision.weight, b->pm, recorded, b->out, values));
            break;
    }
    return decision.state;
}

int main(int argc, char** argv) {
    if (argc != 4 && argc != 6) {
        fprintf(stderr, "usage: %s MODEL.pmsc FRAMES.npy OUT.npy [EPS_MIN EPS_MAX]\n", argv[0]);
        return 2;
    }
    if (pmsc_api_version() / 1000 != PMSC_C_API_VERSION_MAJOR || pmsc_api_version() < PMSC_C_API_VERSION) {
        fprintf(stderr, "replay_c: library API version %d, built against %d\n", (int)pmsc_api_version(),
                PMSC_C_API_VERSION);
        return 1;
    }
    pmsc_model* model = NULL;
    pmsc_multiplier* multiplier = NULL;
    CHECK(pmsc_model_load(argv[1], &model));
    if (argc == 6)
        CHECK(pmsc_multiplier_create_with_eps(model, strtod(argv[4], NULL), strtod(argv[5], NULL),
                                              &multiplier));
    else
        CHECK(pmsc_multiplier_create(model, &multiplier));
    pmsc_model_free(model); /* the multiplier keeps what it needs */

    char error[512];
    npy_frames frames;
    if (npy_frames_read(argv[2], &frames, error, sizeof error) != 0) {
        fprintf(stderr, "replay_c: %s\n", error);
        return 1;
    }
    replay_buffers b = make_buffers(multiplier);
    if (frames.points != b.n || frames.channels != b.c) {
        fprintf(stderr, "replay_c: %s has %zu points x %zu channels, the model %zu x %zu\n", argv[2],
                frames.points, frames.channels, b.n, b.c);
        return 1;
    }
    FILE* out = npy_frames_create(argv[3], frames.frames, b.n, b.c, error, sizeof error);
    if (out == NULL) {
        fprintf(stderr, "replay_c: %s\n", error);
        return 1;
    }
    static const char* const kNames[] = {"hit", "blend", "miss"};
    for (size_t f = 0; f < frames.frames; ++f) {
        const pmsc_cache_state state = replay_frame(multiplier, &b, frames.values + f * b.n * b.c);
        printf("%s\n", kNames[state]);
        if (npy_frames_write(out, b.out, b.n * b.c) != 0) {
            fprintf(stderr, "replay_c: %s: cannot write frame %zu\n", argv[3], f);
            return 1;
        }
    }
    if (fclose(out) != 0) {
        fprintf(stderr, "replay_c: %s: cannot write\n", argv[3]);
        return 1;
    }
    free_buffers(&b);
    npy_frames_free(&frames);
    pmsc_multiplier_free(multiplier);
    return 0;
}
