/* The C API's errors: every bad input gives its status and a one-line message naming the call,
 * never a crash; a successful call clears the message; a runtime is usable from several threads.
 *
 *   pmsc_capi_bad_inputs MODEL.pmsc WORK_DIR
 *
 * MODEL.pmsc is a valid model (pmsc_capi_test_model writes one); WORK_DIR a folder for the
 * broken files this test writes. Prints one line per failed check; exit code 0 when none failed. */
#include <pmsc/pmsc.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <threads.h>

static int failures = 0;

#define EXPECT(condition)                                                    \
    do {                                                                     \
        if (!(condition)) {                                                  \
            fprintf(stderr, "line %d: expected %s\n", __LINE__, #condition); \
            ++failures;                                                      \
        }                                                                    \
    } while (0)

/* The call returns `want`; its message is "" for PMSC_OK, else one non-empty line that starts
 * with the function's name (the text of the call up to its '('). */
#define EXPECT_STATUS(call, want) expect_status((call), (want), #call, __LINE__)

static void expect_status(pmsc_status got, pmsc_status want, const char* call, int line) {
    const char* message = pmsc_last_error();
    const size_t name_length = strcspn(call, "(");
    if (got != want) {
        fprintf(stderr, "line %d: %s returned %s, expected %s (message: %s)\n", line, call,
                pmsc_status_name(got), pmsc_status_name(want), message);
        ++failures;
        return;
    }
    if (want == PMSC_OK) {
        if (message[0] != '\0') {
            fprintf(stderr, "line %d: %s succeeded but left the message \"%s\"\n", line, call, message);
            ++failures;
        }
        return;
    }
    const int one_line = strpbrk(message, "\r\n") == NULL;
    const int named =
        strncmp(message, call, name_length) == 0 && strncmp(message + name_length, ": ", 2) == 0;
    if (!one_line || !named || strlen(message) <= name_length + 2) {
        fprintf(stderr, "line %d: %s: message is not one line naming the call: \"%s\"\n", line, call,
                message);
        ++failures;
    }
}

static void write_file(const char* path, const void* bytes, size_t count) {
    FILE* file = fopen(path, "wb");
    if (file == NULL || fwrite(bytes, 1, count, file) != count || fclose(file) != 0) {
        fprintf(stderr, "cannot write %s\n", path);
        exit(2);
    }
}

/* The bytes of a file (NUL-terminated for convenience), their count in *count. */
static unsigned char* read_file(const char* path, size_t* count) {
    FILE* file = fopen(path, "rb");
    unsigned char* bytes = NULL;
    if (file != NULL && fseek(file, 0, SEEK_END) == 0) {
        const long size = ftell(file);
        bytes = size >= 0 ? malloc((size_t)size + 1) : NULL;
        *count = (size_t)size;
        if (bytes != NULL && (fseek(file, 0, SEEK_SET) != 0 || fread(bytes, 1, *count, file) != *count)) {
            free(bytes);
            bytes = NULL;
        }
    }
    if (file != NULL) fclose(file);
    if (bytes == NULL) {
        fprintf(stderr, "cannot read %s\n", path);
        exit(2);
    }
    return bytes;
}

/* Missing, unreadable, garbage and truncated model files; NULL arguments. */
static void check_loading(const char* model_path, const char* work) {
    char path[4096];
    pmsc_model* model = (pmsc_model*)&model; /* any non-NULL value: a failed load sets NULL */
    snprintf(path, sizeof path, "%s/missing.pmsc", work);
    EXPECT_STATUS(pmsc_model_load(path, &model), PMSC_ERROR_INPUT);
    EXPECT(model == NULL);
    EXPECT(strstr(pmsc_last_error(), "missing.pmsc") != NULL);
    EXPECT_STATUS(pmsc_model_load(work, &model), PMSC_ERROR_INPUT); /* a folder */
    EXPECT_STATUS(pmsc_model_load(NULL, &model), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_model_load(model_path, NULL), PMSC_ERROR_INVALID_ARGUMENT);

    snprintf(path, sizeof path, "%s/garbage.pmsc", work);
    const char garbage[] = "this is not a model\nbut it has\nseveral lines\n";
    write_file(path, garbage, sizeof garbage);
    EXPECT_STATUS(pmsc_model_load(path, &model), PMSC_ERROR_INPUT);
    write_file(path, "", 0);
    EXPECT_STATUS(pmsc_model_load(path, &model), PMSC_ERROR_INPUT);

    size_t size = 0;
    unsigned char* bytes = read_file(model_path, &size);
    snprintf(path, sizeof path, "%s/truncated.pmsc", work);
    write_file(path, bytes, size / 2);
    EXPECT_STATUS(pmsc_model_load(path, &model), PMSC_ERROR_INPUT);
    bytes[size / 2] ^= 0x40; /* one flipped bit: the checksum no longer matches */
    EXPECT_STATUS(pmsc_model_load_memory(bytes, size, &model), PMSC_ERROR_INPUT);
    bytes[size / 2] ^= 0x40;
    EXPECT_STATUS(pmsc_model_load_memory(bytes, size - 1, &model), PMSC_ERROR_INPUT);
    EXPECT_STATUS(pmsc_model_load_memory(garbage, sizeof garbage, &model), PMSC_ERROR_INPUT);
    EXPECT_STATUS(pmsc_model_load_memory(NULL, 10, &model), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_model_load_memory(bytes, size, &model), PMSC_OK);
    EXPECT(model != NULL);
    pmsc_model_free(model);
    free(bytes);
    pmsc_model_free(NULL);
    pmsc_multiplier_free(NULL);
}

/* Sizes, key points and thresholds of a valid model, and NULL or wrongly sized arguments. */
static void check_model(const pmsc_model* model, size_t* n, size_t* c, size_t* k, size_t* coords) {
    size_t m = 0, regions = 1;
    EXPECT_STATUS(pmsc_model_point_count(model, n), PMSC_OK);
    EXPECT_STATUS(pmsc_model_channel_count(model, c), PMSC_OK);
    EXPECT_STATUS(pmsc_model_key_count(model, k), PMSC_OK);
    EXPECT_STATUS(pmsc_model_basis_size(model, &m), PMSC_OK);
    EXPECT_STATUS(pmsc_model_coord_count(model, coords), PMSC_OK);
    EXPECT_STATUS(pmsc_model_region_count(model, &regions), PMSC_OK);
    EXPECT(*n == 50 && *c == 3 && *k == 6 && m == 3 && *coords == 3 && regions == 0);
    EXPECT_STATUS(pmsc_model_point_count(NULL, n), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_model_channel_count(model, NULL), PMSC_ERROR_INVALID_ARGUMENT);

    int64_t keys[7];
    EXPECT_STATUS(pmsc_model_key_points(model, keys, 6), PMSC_OK);
    for (int i = 0; i < 6; ++i) EXPECT(keys[i] >= 0 && keys[i] < 50);
    EXPECT_STATUS(pmsc_model_key_points(model, keys, 5), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_model_key_points(model, keys, 7), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_model_key_points(model, NULL, 6), PMSC_ERROR_INVALID_ARGUMENT);

    double eps_min = -1, eps_max = -1;
    EXPECT_STATUS(pmsc_model_eps(model, &eps_min, &eps_max), PMSC_OK);
    EXPECT(eps_min >= 0 && eps_max >= eps_min);
    EXPECT_STATUS(pmsc_model_eps(model, &eps_min, NULL), PMSC_ERROR_INVALID_ARGUMENT);

    /* This model has no tolerance, so no sentinels (replay_c checks a model's real ones). */
    size_t sentinels = 7;
    EXPECT_STATUS(pmsc_model_sentinel_count(model, &sentinels), PMSC_OK);
    EXPECT(sentinels == 0);
    EXPECT_STATUS(pmsc_model_sentinel_count(model, NULL), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_model_sentinels(model, NULL, 0), PMSC_OK);
    EXPECT_STATUS(pmsc_model_sentinels(model, keys, 1), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_model_sentinels(NULL, NULL, 0), PMSC_ERROR_INVALID_ARGUMENT);
}

/* Thresholds: bad ones are refused, good ones are used; the model's own otherwise. */
static void check_eps(const pmsc_model* model) {
    const double bad[][2] = {{0.2, 0.1}, {-1.0, 1.0}, {NAN, 1.0}, {0.0, INFINITY}, {0.0, NAN}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; ++i) {
        pmsc_multiplier* m = (pmsc_multiplier*)&m;
        EXPECT_STATUS(pmsc_multiplier_create_with_eps(model, bad[i][0], bad[i][1], &m),
                      PMSC_ERROR_INVALID_ARGUMENT);
        EXPECT(m == NULL);
    }
    pmsc_multiplier* m = NULL;
    EXPECT_STATUS(pmsc_multiplier_create_with_eps(NULL, 0.1, 0.2, &m), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_create(model, NULL), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_create_with_eps(model, 0.1, 0.3, &m), PMSC_OK);
    double eps_min = 0, eps_max = 0;
    EXPECT_STATUS(pmsc_multiplier_eps(m, &eps_min, &eps_max), PMSC_OK);
    EXPECT(eps_min == 0.1 && eps_max == 0.3);
    pmsc_decision d;
    EXPECT_STATUS(pmsc_multiplier_decide(m, 0.05, &d), PMSC_OK);
    EXPECT(d.state == PMSC_HIT && d.weight == 0);
    EXPECT_STATUS(pmsc_multiplier_decide(m, 0.2, &d), PMSC_OK);
    EXPECT(d.state == PMSC_BLEND && fabs(d.weight - 0.5) < 1e-12);
    EXPECT_STATUS(pmsc_multiplier_decide(m, 0.3, &d), PMSC_OK);
    EXPECT(d.state == PMSC_MISS && d.weight == 1);
    EXPECT_STATUS(pmsc_multiplier_decide(m, NAN, &d), PMSC_OK); /* broken keys: a miss */
    EXPECT(d.state == PMSC_MISS && d.weight == 1);
    EXPECT_STATUS(pmsc_multiplier_decide(m, 0.2, NULL), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_decide(NULL, 0.2, &d), PMSC_ERROR_INVALID_ARGUMENT);
    pmsc_multiplier_free(m);
}

/* Projection and reconstruction with NULL, wrongly sized, overlapping and out-of-range arguments. */
static void check_runtime(const pmsc_multiplier* m, size_t n, size_t c, size_t k, size_t nc) {
    double keys[18], coords[3], out[150], error = -1;
    for (size_t i = 0; i < k * c; ++i) keys[i] = 0.1 * (double)i;
    EXPECT_STATUS(pmsc_multiplier_project(m, keys, k * c, coords, nc), PMSC_OK);
    EXPECT_STATUS(pmsc_multiplier_project(NULL, keys, k * c, coords, nc), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_project(m, NULL, k * c, coords, nc), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_project(m, keys, k * c - 1, coords, nc), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_project(m, keys, k * c, NULL, nc), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_project(m, keys, k * c, coords, nc + 1), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_project(m, keys, k * c, keys + 2, nc), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_key_error(m, keys, k * c, coords, nc, &error), PMSC_OK);
    EXPECT(error >= 0);
    EXPECT_STATUS(pmsc_multiplier_key_error(m, keys, k * c, coords, nc, NULL), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_key_error(m, keys, k * c, coords, 0, &error), PMSC_ERROR_INVALID_ARGUMENT);
    keys[0] = NAN;
    EXPECT_STATUS(pmsc_multiplier_key_error(m, keys, k * c, coords, nc, &error), PMSC_OK);
    EXPECT(isnan(error));

    EXPECT_STATUS(pmsc_multiplier_reconstruct(m, coords, nc, out, n * c), PMSC_OK);
    EXPECT_STATUS(pmsc_multiplier_reconstruct(m, coords, nc, out, n * c - 1), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_reconstruct(m, coords, nc, NULL, n * c), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_reconstruct(m, out + 1, nc, out, n * c), PMSC_ERROR_INVALID_ARGUMENT);

    const int64_t points[3] = {49, 0, 49};
    double some[9];
    EXPECT_STATUS(pmsc_multiplier_reconstruct_points(m, coords, nc, points, 3, some, 9), PMSC_OK);
    for (size_t ch = 0; ch < c; ++ch) {
        EXPECT(fabs(some[ch] - out[49 * c + ch]) < 1e-12 && fabs(some[c + ch] - out[ch]) < 1e-12);
        EXPECT(some[2 * c + ch] == some[ch]);
    }
    const int64_t outside[2] = {0, 50}, negative[1] = {-1};
    EXPECT_STATUS(pmsc_multiplier_reconstruct_points(m, coords, nc, outside, 2, some, 6),
                  PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT(strstr(pmsc_last_error(), "points[1] = 50") != NULL);
    EXPECT_STATUS(pmsc_multiplier_reconstruct_points(m, coords, nc, negative, 1, some, 3),
                  PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_reconstruct_points(m, coords, nc, points, 3, some, 8),
                  PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_reconstruct_points(m, coords, nc, NULL, 3, some, 9),
                  PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_reconstruct_points(m, coords, nc, NULL, 0, NULL, 0), PMSC_OK);

    int stands = 0;
    EXPECT_STATUS(pmsc_multiplier_check_sentinels(m, coords, nc, NULL, 0, &stands), PMSC_OK);
    EXPECT(stands == 1);
    EXPECT_STATUS(pmsc_multiplier_check_sentinels(m, coords, nc, some, 3, &stands),
                  PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT(strstr(pmsc_last_error(), "pmsc_multiplier_check_sentinels") != NULL);
    EXPECT_STATUS(pmsc_multiplier_check_sentinels(m, coords, nc - 1, NULL, 0, &stands),
                  PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_check_sentinels(m, coords, nc, NULL, 0, NULL), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_check_sentinels(NULL, coords, nc, NULL, 0, &stands),
                  PMSC_ERROR_INVALID_ARGUMENT);
}

/* pmsc_blend: the weight's range, NULL buffers, in place, overlap. */
static void check_blend(void) {
    double pm[4] = {1, 2, 3, 4}, full[4] = {5, 6, 7, 8}, out[4];
    EXPECT_STATUS(pmsc_blend(0.25, pm, full, out, 4), PMSC_OK);
    for (int i = 0; i < 4; ++i) EXPECT(out[i] == (1.0 - 0.25) * pm[i] + 0.25 * full[i]);
    EXPECT_STATUS(pmsc_blend(0.25, pm, full, full, 4), PMSC_OK); /* in place */
    for (int i = 0; i < 4; ++i) EXPECT(full[i] == out[i]);
    EXPECT_STATUS(pmsc_blend(1.5, pm, full, out, 4), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_blend(-0.1, pm, full, out, 4), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_blend(NAN, pm, full, out, 4), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_blend(0.5, NULL, full, out, 4), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_blend(0.5, pm, full, pm + 1, 3), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_blend(0.5, NULL, NULL, NULL, 0), PMSC_OK);
}

/* pmsc_multiplier_blend: the test model has no tolerance, so it is pmsc_blend point by point; a
 * count that is not a multiple of C, a NULL runtime and a bad weight are refused. */
static void check_multiplier_blend(const pmsc_multiplier* m, size_t c) {
    double pm[6] = {1, 2, 3, 4, 5, 6}, full[6] = {6, 5, 4, 3, 2, 1}, out[6], plain[6];
    if (c != 3) return;
    EXPECT_STATUS(pmsc_multiplier_blend(m, 0.25, pm, full, out, 6), PMSC_OK);
    EXPECT_STATUS(pmsc_blend(0.25, pm, full, plain, 6), PMSC_OK);
    for (int i = 0; i < 6; ++i) EXPECT(out[i] == plain[i]);
    EXPECT_STATUS(pmsc_multiplier_blend(m, 0.25, pm, full, out, 4), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_blend(NULL, 0.25, pm, full, out, 6), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_blend(m, 1.5, pm, full, out, 6), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_blend(m, 0.5, NULL, full, out, 6), PMSC_ERROR_INVALID_ARGUMENT);
    EXPECT_STATUS(pmsc_multiplier_blend(m, 0.5, NULL, NULL, NULL, 0), PMSC_OK);
}

/* Two threads share one runtime: each gets the serial results and its own messages. */
typedef struct thread_job {
    const pmsc_multiplier* m;
    double scale;
    double expected[150];
    int mismatches;
} thread_job;

static void run_frame(const pmsc_multiplier* m, double scale, double out[150]) {
    double keys[18], coords[3];
    for (int i = 0; i < 18; ++i) keys[i] = scale * sin(0.3 * i);
    if (pmsc_multiplier_project(m, keys, 18, coords, 3) != PMSC_OK ||
        pmsc_multiplier_reconstruct(m, coords, 3, out, 150) != PMSC_OK)
        out[0] = NAN;
}

static int thread_body(void* arg) {
    thread_job* job = arg;
    double out[150];
    for (int round = 0; round < 200; ++round) {
        run_frame(job->m, job->scale, out);
        job->mismatches += memcmp(out, job->expected, sizeof out) != 0;
        /* An error on this thread: its message names this call, whatever the other thread does. */
        if (pmsc_blend(job->scale, out, out, out, 150) != PMSC_ERROR_INVALID_ARGUMENT ||
            strstr(pmsc_last_error(), "pmsc_blend: weight") != pmsc_last_error())
            ++job->mismatches;
    }
    return 0;
}

static void check_threads(const pmsc_multiplier* m) {
    thread_job jobs[2] = {{m, 2.0, {0}, 0}, {m, 3.0, {0}, 0}};
    thrd_t threads[2];
    for (int t = 0; t < 2; ++t) run_frame(m, jobs[t].scale, jobs[t].expected);
    EXPECT_STATUS(pmsc_multiplier_eps(m, NULL, NULL), PMSC_ERROR_INVALID_ARGUMENT);
    for (int t = 0; t < 2; ++t) EXPECT(thrd_create(&threads[t], thread_body, &jobs[t]) == thrd_success);
    for (int t = 0; t < 2; ++t) thrd_join(threads[t], NULL);
    EXPECT(jobs[0].mismatches == 0 && jobs[1].mismatches == 0);
    EXPECT(strncmp(pmsc_last_error(), "pmsc_multiplier_eps: ", 21) == 0); /* this thread's, unchanged */
}

int main(int argc, char** argv) {
    if (argc != 3) {
        fprintf(stderr, "usage: %s MODEL.pmsc WORK_DIR\n", argv[0]);
        return 2;
    }
    EXPECT(pmsc_api_version() == PMSC_C_API_VERSION);
    EXPECT(strcmp(pmsc_status_name(PMSC_OK), "ok") == 0);
    EXPECT(strcmp(pmsc_status_name(PMSC_ERROR_INPUT), "bad input") == 0);
    EXPECT(strcmp(pmsc_status_name(99), "unknown status") == 0);
    check_loading(argv[1], argv[2]);

    pmsc_model* model = NULL;
    pmsc_multiplier* m = NULL;
    size_t n = 0, c = 0, k = 0, coords = 0;
    EXPECT_STATUS(pmsc_model_load(argv[1], &model), PMSC_OK);
    if (model == NULL) return 1;
    check_model(model, &n, &c, &k, &coords);
    check_eps(model);
    EXPECT_STATUS(pmsc_multiplier_create(model, &m), PMSC_OK);
    pmsc_model_free(model); /* the runtime holds the model's data */
    const pmsc_model* own = NULL;
    EXPECT_STATUS(pmsc_multiplier_model(m, &own), PMSC_OK);
    EXPECT_STATUS(pmsc_model_point_count(own, &n), PMSC_OK);
    EXPECT_STATUS(pmsc_multiplier_model(m, NULL), PMSC_ERROR_INVALID_ARGUMENT);
    if (m != NULL && n == 50 && c == 3 && k == 6 && coords == 3) {
        check_runtime(m, n, c, k, coords);
        check_threads(m);
    }
    check_blend();
    if (m != NULL) check_multiplier_blend(m, c);
    pmsc_multiplier_free(m);
    if (failures != 0)
        fprintf(stderr, "%d checks failed\n", failures);
    else
        printf("pmsc C API bad inputs: ok\n");
    return failures == 0 ? 0 : 1;
}
