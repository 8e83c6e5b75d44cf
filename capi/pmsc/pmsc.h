/* pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar): the C API.
 *
 * The runtime of a trained model, for programs that cannot share C++ types with pmsc: a DCC
 * plug-in built with another compiler, another C++ standard library or in C. C11 or C++; the
 * library (libpmsc_c.so, CMake target pmsc::c) exports only the functions below.
 *
 *   load a model (.pmsc, from `pmsc train`)          pmsc_model_load
 *   make its runtime (thresholds eps)                 pmsc_multiplier_create
 *   per frame: compute the key points' values yourself, then
 *     key values -> pose-space coordinates            pmsc_multiplier_project      (section 6)
 *     the key points' own error (the model's measure) pmsc_multiplier_key_error
 *     hit, blend or miss, and the weight of the full  pmsc_multiplier_decide       (section 5)
 *     all points, or chosen points                    pmsc_multiplier_reconstruct[_points]
 *     a blend of the PM result and the full result    pmsc_multiplier_blend (as the engine blends)
 *
 * Errors. Every function returns a pmsc_status, except pmsc_api_version, pmsc_status_name,
 * pmsc_last_error and the *_free functions (which cannot fail). PMSC_OK is 0. Every function that
 * returns a status also sets the calling thread's message (pmsc_last_error): empty after PMSC_OK,
 * otherwise one line without a newline that starts with the function's name and names the
 * problem. No C++ exception ever leaves a function of this API; a NULL pointer, a buffer length
 * that differs from what the call reads or writes, an index out of range, bad thresholds, a
 * missing, unreadable or corrupt file are all reported through the status. On failure the output
 * buffers hold unspecified values and an output handle is set to NULL.
 *
 * Buffers. Every buffer comes with its length in elements (not bytes), which must equal what the
 * call reads or writes: K*C key values (K key points in model order, channel-minor: value of key
 * point i, channel c at [i*C + c]), pmsc_model_coord_count() coordinates, N*C point values
 * (channel-minor). Input and output buffers must not overlap, except where a function says so.
 *
 * Threads. pmsc_model and pmsc_multiplier are immutable once created: any number of threads may
 * call any function on the same handle at once, each with its own buffers. A handle must not be
 * freed while another thread uses it. Messages are per thread.
 *
 * Models with regions (local fail-through) and cross models load and run here as whole-frame
 * models: their regions and cross state are not used, so a frame that does not hit fails through
 * whole, as `pmsc replay --whole-frame-fail-through` does. A hit is checked as the engine checks
 * it with pmsc_model_sentinels and pmsc_multiplier_check_sentinels (since API 1.2): compute the
 * sentinels beside the keys, and a hit that fails the check is computed whole and blended with
 * weight 0. The engine's further check of a hit only one part of the predicted key error certifies
 * (region keys, key neighbours) is not part of this API.
 */
#ifndef PMSC_PMSC_H
#define PMSC_PMSC_H

#include <stddef.h>
#include <stdint.h>

/* The API's version: a new minor version only adds functions, a new major version changes or
 * removes some. A program built against this header runs with a library of the same major
 * version and a minor version at least this one's (compare with pmsc_api_version()). */
#define PMSC_C_API_VERSION_MAJOR 1
#define PMSC_C_API_VERSION_MINOR 2
#define PMSC_C_API_VERSION (PMSC_C_API_VERSION_MAJOR * 1000 + PMSC_C_API_VERSION_MINOR)

#if defined(_WIN32)
#if defined(PMSC_C_BUILDING)
#define PMSC_C_API __declspec(dllexport)
#else
#define PMSC_C_API __declspec(dllimport)
#endif
#else
#define PMSC_C_API __attribute__((visibility("default")))
#endif

#ifdef __cplusplus
#define PMSC_C_NOEXCEPT noexcept
extern "C" {
#else
#define PMSC_C_NOEXCEPT
#endif

/* ---- versions, status codes, messages ------------------------------------------------------ */

/** What a call did. */
typedef int32_t pmsc_status;
enum {
    PMSC_OK = 0,
    /** A NULL pointer, a buffer length that is not what the call reads or writes, a point index
     *  outside [0, N), thresholds that are not 0 <= eps_min <= eps_max (both finite), a blend
     *  weight outside [0, 1]. */
    PMSC_ERROR_INVALID_ARGUMENT = 1,
    /** A model file (or buffer) that is missing, unreadable, truncated, corrupt, or written by a
     *  newer pmsc: the user can fix it, retrying cannot. */
    PMSC_ERROR_INPUT = 2,
    /** Memory could not be allocated. */
    PMSC_ERROR_OUT_OF_MEMORY = 3,
    /** Anything else (a bug in pmsc: please report the message). */
    PMSC_ERROR_INTERNAL = 4
};

/** PMSC_C_API_VERSION of the library. */
PMSC_C_API int32_t pmsc_api_version(void) PMSC_C_NOEXCEPT;

/** A short name of a status ("ok", "invalid argument", ...; "unknown status" for others).
 *  Static storage. */
PMSC_C_API const char* pmsc_status_name(pmsc_status status) PMSC_C_NOEXCEPT;

/** The calling thread's message from its last call that returned a status: "" after PMSC_OK,
 *  else one line naming the function and the problem. Never NULL. Valid until this thread's
 *  next call to this API. */
PMSC_C_API const char* pmsc_last_error(void) PMSC_C_NOEXCEPT;

/* ---- the model --------------------------------------------------------------------------- */

/** A trained model (basis, mean, key points, projector, thresholds). Immutable. */
typedef struct pmsc_model pmsc_model;

/** Reads and checks a .pmsc model file.
 *  @param[in]  path   file name, handed to the operating system as it is
 *  @param[out] model  the model, to free with pmsc_model_free; NULL on failure
 *  @return PMSC_ERROR_INPUT for a missing, unreadable, truncated or corrupt file (the message
 *          names the file and what is wrong with it). */
PMSC_C_API pmsc_status pmsc_model_load(const char* path, pmsc_model** model) PMSC_C_NOEXCEPT;

/** Reads and checks a model from the bytes of a .pmsc file (a model embedded in a scene file).
 *  The model keeps no reference to them: the buffer may be freed when the call returns. */
PMSC_C_API pmsc_status pmsc_model_load_memory(const void* bytes, size_t byte_count,
                                              pmsc_model** model) PMSC_C_NOEXCEPT;

/** Frees a model. NULL is allowed. Multipliers made from it stay valid: they hold the data. */
PMSC_C_API void pmsc_model_free(pmsc_model* model) PMSC_C_NOEXCEPT;

/** N, the points of a frame. */
PMSC_C_API pmsc_status pmsc_model_point_count(const pmsc_model* model, size_t* points) PMSC_C_NOEXCEPT;
/** C, the channels (values) of a point. */
PMSC_C_API pmsc_status pmsc_model_channel_count(const pmsc_model* model, size_t* channels) PMSC_C_NOEXCEPT;
/** K, the key points whose values a frame needs. */
PMSC_C_API pmsc_status pmsc_model_key_count(const pmsc_model* model, size_t* keys) PMSC_C_NOEXCEPT;
/** M, the basis vectors. */
PMSC_C_API pmsc_status pmsc_model_basis_size(const pmsc_model* model, size_t* basis_size) PMSC_C_NOEXCEPT;
/** The pose-space coordinates of a frame: M, or M*C when the channels share the basis
 *  (`pmsc train --shared-channels`). The length of every coordinate buffer. */
PMSC_C_API pmsc_status pmsc_model_coord_count(const pmsc_model* model, size_t* coords) PMSC_C_NOEXCEPT;
/** The regions of a model trained with `--regions` (0 for none). The C API does not use them. */
PMSC_C_API pmsc_status pmsc_model_region_count(const pmsc_model* model, size_t* regions) PMSC_C_NOEXCEPT;

/** Copies the K key point indices, in model order (the order of the key values), into
 *  key_points[0 .. K). key_point_count must be K. */
PMSC_C_API pmsc_status pmsc_model_key_points(const pmsc_model* model, int64_t* key_points,
                                             size_t key_point_count) PMSC_C_NOEXCEPT;

/** The soft-cache thresholds stored in the model (`pmsc train`, `--tolerance`): at or below
 *  eps_min a frame hits, at or above eps_max it misses. In the model's key error, data units. */
PMSC_C_API pmsc_status pmsc_model_eps(const pmsc_model* model, double* eps_min,
                                      double* eps_max) PMSC_C_NOEXCEPT;

/** S, the sentinels of the model: points `pmsc train --tolerance` spread over what the training saw
 *  move, to be computed beside every hit's keys (docs/calibration.md). 0 for a model without.
 *  Since API 1.2. */
PMSC_C_API pmsc_status pmsc_model_sentinel_count(const pmsc_model* model, size_t* count) PMSC_C_NOEXCEPT;

/** Copies the S sentinel indices into sentinels[0 .. S), the order pmsc_multiplier_check_sentinels
 *  takes their values in. count must be S (0 with NULL for a model without). Since API 1.2. */
PMSC_C_API pmsc_status pmsc_model_sentinels(const pmsc_model* model, int64_t* sentinels,
                                            size_t count) PMSC_C_NOEXCEPT;

/* ---- the runtime ------------------------------------------------------------------------- */

/** The runtime of one model: projection, key error, soft-cache decision, reconstruction. Holds
 *  its own reference to the model's data and precomputed tables. Immutable and safe to use
 *  from any number of threads at once. */
typedef struct pmsc_multiplier pmsc_multiplier;

/** The soft cache's decision for a frame (section 5). */
typedef int32_t pmsc_cache_state;
enum {
    PMSC_HIT = 0,   /**< use the point-multiplication result; the full calculation is not needed */
    PMSC_BLEND = 1, /**< compute both and blend them with pmsc_blend */
    PMSC_MISS = 2   /**< fail through: compute every point with the full calculation */
};

typedef struct pmsc_decision {
    pmsc_cache_state state;
    /** Weight of the FULL result: output = (1 - weight) * pm + weight * full. 0 for a hit, 1 for
     *  a miss, in (0, 1) for a blend. */
    double weight;
} pmsc_decision;

/** A runtime with the model's own thresholds. */
PMSC_C_API pmsc_status pmsc_multiplier_create(const pmsc_model* model,
                                              pmsc_multiplier** multiplier) PMSC_C_NOEXCEPT;

/** A runtime with the caller's thresholds (like `pmsc replay --eps MIN,MAX`).
 *  @return PMSC_ERROR_INVALID_ARGUMENT unless 0 <= eps_min <= eps_max, both finite. */
PMSC_C_API pmsc_status pmsc_multiplier_create_with_eps(const pmsc_model* model, double eps_min,
                                                       double eps_max,
                                                       pmsc_multiplier** multiplier) PMSC_C_NOEXCEPT;

/** Frees a runtime. NULL is allowed. */
PMSC_C_API void pmsc_multiplier_free(pmsc_multiplier* multiplier) PMSC_C_NOEXCEPT;

/** The model a runtime was made from, for its sizes. Owned by the runtime: valid while it is,
 *  even after the caller freed its own pmsc_model. Not to be freed. */
PMSC_C_API pmsc_status pmsc_multiplier_model(const pmsc_multiplier* multiplier,
                                             const pmsc_model** model) PMSC_C_NOEXCEPT;

/** The thresholds this runtime decides with. */
PMSC_C_API pmsc_status pmsc_multiplier_eps(const pmsc_multiplier* multiplier, double* eps_min,
                                           double* eps_max) PMSC_C_NOEXCEPT;

/** Pose-space coordinates of a frame from its key values: coords = P (keys - mean at the keys),
 *  P the least-squares projector (section 6).
 *  @param[in]  key_values  K*C values computed at the key points (pmsc_model_key_points)
 *  @param[out] coords      pmsc_model_coord_count() coordinates */
PMSC_C_API pmsc_status pmsc_multiplier_project(const pmsc_multiplier* multiplier, const double* key_values,
                                               size_t key_value_count, double* coords,
                                               size_t coord_count) PMSC_C_NOEXCEPT;

/** The model's key error, from each key point's residual: the Euclidean norm (over channels) of
 *  the difference between its computed value and its value reconstructed from coords. The
 *  measure is the one `pmsc train` calibrated the thresholds for (`pmsc inspect` names it): by
 *  default with a tolerance the predicted point error (the tolerance times the smaller of the key
 *  RMS and the largest leave-one-out key error, each over its own threshold), else the RMS of the
 *  residuals over the K keys, or the largest (leave-one-out) key's (docs/calibration.md).
 *  Data units; what the thresholds are compared with. NaN when a key value is NaN or infinite
 *  (pmsc_multiplier_decide makes that a miss).
 *  @param[in] coords  the coordinates pmsc_multiplier_project gave for these key values */
PMSC_C_API pmsc_status pmsc_multiplier_key_error(const pmsc_multiplier* multiplier, const double* key_values,
                                                 size_t key_value_count, const double* coords,
                                                 size_t coord_count, double* key_error) PMSC_C_NOEXCEPT;

/** Hit, blend or miss for a key error: at or below eps_min a hit (weight 0), at or above eps_max
 *  a miss (weight 1), in between a blend with weight (error - eps_min) / (eps_max - eps_min).
 *  A NaN or infinite error is a miss (not an error). eps_min == eps_max is a hard switch. */
PMSC_C_API pmsc_status pmsc_multiplier_decide(const pmsc_multiplier* multiplier, double key_error,
                                              pmsc_decision* decision) PMSC_C_NOEXCEPT;

/** Every point of the frame: out = mean + basis coords, N*C values, clamped at 0 when the model
 *  was trained on values that are all >= 0 (pmsc inspect: "output clamped at 0"), as every
 *  reconstruction below. */
PMSC_C_API pmsc_status pmsc_multiplier_reconstruct(const pmsc_multiplier* multiplier, const double* coords,
                                                   size_t coord_count, double* out,
                                                   size_t out_count) PMSC_C_NOEXCEPT;

/** Only the given points, in the given order: out[i*C + c] is channel c of points[i]. Each index
 *  must be in [0, N); repeats are allowed. point_count may be 0 (points and out may then be
 *  NULL). out_count must be point_count*C. */
PMSC_C_API pmsc_status pmsc_multiplier_reconstruct_points(const pmsc_multiplier* multiplier,
                                                          const double* coords, size_t coord_count,
                                                          const int64_t* points, size_t point_count,
                                                          double* out, size_t out_count) PMSC_C_NOEXCEPT;

/** Whether a hit stands at its sentinels, as the engine decides it: *stands is 1 when point
 *  multiplication (coords) is within 0.8 of the model's tolerance of every sentinel's computed
 *  value, else 0, and then the frame is to be computed whole and blended with weight 0
 *  (pmsc_multiplier_blend), which keeps every point within the tolerance. A NaN value fails.
 *  1 for a model without sentinels (values NULL, value_count 0). Since API 1.2.
 *  @param[in] values  S*C values computed at the sentinels, in pmsc_model_sentinels' order */
PMSC_C_API pmsc_status pmsc_multiplier_check_sentinels(const pmsc_multiplier* multiplier,
                                                       const double* coords, size_t coord_count,
                                                       const double* values, size_t value_count,
                                                       int* stands) PMSC_C_NOEXCEPT;

/** A blended frame or set of points as `pmsc replay` and the engine blend them: point by point,
 *  out = (1 - w) * pm + w * full with w = max(weight, 1 - T / e), e the Euclidean distance (over
 *  the point's C channels) between pm and full and T the model's tolerance, wherever e > T: a
 *  blended point is never handed back further than T from its full value (a model without a
 *  tolerance blends with weight alone). Computed inside the library so the result has their bits
 *  whatever compiler and flags the caller builds with. out may be the same buffer as pm or full.
 *  weight must be in [0, 1]. Since API 1.1.
 *  @param[in] count  the number of values of each buffer: a multiple of C (N*C for a whole frame) */
PMSC_C_API pmsc_status pmsc_multiplier_blend(const pmsc_multiplier* multiplier, double weight,
                                             const double* pm, const double* full, double* out,
                                             size_t count) PMSC_C_NOEXCEPT;

/** A blend element by element: out[i] = (1.0 - weight) * pm[i] + weight * full[i], with no
 *  tolerance (pmsc_multiplier_blend is what the engine does). Computed inside the library so the
 *  result has the same bits whatever compiler and flags the caller builds with (a compiler may
 *  fuse a multiply and an add into one instruction, which changes the last bit). out may be the
 *  same buffer as pm or full. weight must be in [0, 1].
 *  @param[in] count  the number of values of each buffer (N*C for a whole frame) */
PMSC_C_API pmsc_status pmsc_blend(double weight, const double* pm, const double* full, double* out,
                                  size_t count) PMSC_C_NOEXCEPT;

#ifdef __cplusplus
}
#endif

#endif /* PMSC_PMSC_H */
