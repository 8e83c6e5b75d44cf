/* Embeds pmsc from C: loads a model, projects one frame's key values and reconstructs every point.
 *   pmsc_c_consumer MODEL.pmsc
 * Prints "pmsc C consumer: ok" and what it did. */
#include <pmsc/pmsc.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#define CHECK(call)                                                      \
    do {                                                                 \
        if ((call) != PMSC_OK) {                                         \
            fprintf(stderr, "pmsc C consumer: %s\n", pmsc_last_error()); \
            return 1;                                                    \
        }                                                                \
    } while (0)

int main(int argc, char** argv) {
    if (argc != 2) return 2;
    if (pmsc_api_version() / 1000 != PMSC_C_API_VERSION_MAJOR) return 1;
    pmsc_model* model = NULL;
    pmsc_multiplier* multiplier = NULL;
    size_t n = 0, c = 0, k = 0, coord_count = 0;
    CHECK(pmsc_model_load(argv[1], &model));
    CHECK(pmsc_model_point_count(model, &n));
    CHECK(pmsc_model_channel_count(model, &c));
    CHECK(pmsc_model_key_count(model, &k));
    CHECK(pmsc_model_coord_count(model, &coord_count));
    CHECK(pmsc_multiplier_create(model, &multiplier));
    pmsc_model_free(model);

    /* The key values a calculation would give at the key points; here a made-up pose. */
    double* keys = malloc(k * c * sizeof(double));
    double* coords = malloc(coord_count * sizeof(double));
    double* frame = malloc(n * c * sizeof(double));
    if (keys == NULL || coords == NULL || frame == NULL) return 1;
    for (size_t i = 0; i < k * c; ++i) keys[i] = sin(0.7 * (double)i);
    double key_error = 0;
    pmsc_decision decision;
    CHECK(pmsc_multiplier_project(multiplier, keys, k * c, coords, coord_count));
    CHECK(pmsc_multiplier_key_error(multiplier, keys, k * c, coords, coord_count, &key_error));
    CHECK(pmsc_multiplier_decide(multiplier, key_error, &decision));
    CHECK(pmsc_multiplier_reconstruct(multiplier, coords, coord_count, frame, n * c));
    for (size_t i = 0; i < n * c; ++i) {
        if (!isfinite(frame[i])) return 1;
    }
    static const char* const kStates[] = {"hit", "blend", "miss"};
    printf("%zu points x %zu channels from %zu keys, key error %.3g (%s); pmsc C consumer: ok\n", n, c, k,
           key_error, kStates[decision.state]);
    free(keys);
    free(coords);
    free(frame);
    pmsc_multiplier_free(multiplier);
    return 0;
}
