// The C API (pmsc/pmsc.h): a thin layer over pmsc::PointMultiplier, pmsc::SoftCachePolicy and the
// model reader. Every function runs its body inside guarded(), which turns every C++ exception into
// a status and a one-line message, so none crosses the C boundary.
#include "pmsc/pmsc.h"

#include "pmsc/Errors.h"
#include "pmsc/HitCheck.h"
#include "pmsc/ModelIO.h"
#include "pmsc/PointMultiplier.h"
#include "pmsc/SoftCache.h"

#include <cmath>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <new>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

static_assert(PMSC_HIT == static_cast<int>(pmsc::CacheState::Hit));
static_assert(PMSC_BLEND == static_cast<int>(pmsc::CacheState::Blend));
static_assert(PMSC_MISS == static_cast<int>(pmsc::CacheState::Miss));

/// A model shared by its handle and every runtime made from it, so freeing the handle first is safe.
struct pmsc_model {
    std::shared_ptr<const pmsc::Model> model;
};

struct pmsc_multiplier {
    pmsc_multiplier(std::shared_ptr<const pmsc::Model> shared, const pmsc::SoftCachePolicy& p)
        : model{std::move(shared)}, multiplier(*model.model), policy(p), check(*model.model, multiplier) {}

    pmsc_model model;                  // declared first: the multiplier refers to *model.model
    pmsc::PointMultiplier multiplier;  // const methods, safe to call concurrently
    pmsc::SoftCachePolicy policy;
    pmsc::HitCheck check;  // after the multiplier it refers to; const methods
};

namespace {

/// The calling thread's message. A fixed buffer, so recording an error cannot fail.
constexpr std::size_t kMessageBytes = 1024;
thread_local char tlsMessage[kMessageBytes] = {};

/// "function: what" as one line: line breaks and tabs become spaces, too long is cut.
void setMessage(std::string_view function, std::string_view what) noexcept {
    std::size_t at = 0;
    const auto put = [&](std::string_view text) {
        for (const char ch : text) {
            if (at + 1 >= kMessageBytes) break;
            tlsMessage[at++] = (ch == '\n' || ch == '\r' || ch == '\t') ? ' ' : ch;
        }
    };
    put(function);
    put(": ");
    put(what.empty() ? std::string_view("unknown error") : what);
    tlsMessage[at] = '\0';
}

/// A bad argument found by this layer (pmsc's own std::invalid_argument maps to the same status).
struct ArgumentError : std::invalid_argument {
    using std::invalid_argument::invalid_argument;
};

/// Runs `body`; maps what it throws to a status and the thread's message.
template <class Body>
pmsc_status guarded(std::string_view function, Body&& body) noexcept {
    pmsc_status status = PMSC_ERROR_INTERNAL;
    try {
        std::invoke(std::forward<Body>(body));
        tlsMessage[0] = '\0';
        return PMSC_OK;
    } catch (const pmsc::InputError& e) {
        status = PMSC_ERROR_INPUT;
        setMessage(function, e.what());
    } catch (const std::invalid_argument& e) {
        status = PMSC_ERROR_INVALID_ARGUMENT;
        setMessage(function, e.what());
    } catch (const std::bad_alloc&) {
        status = PMSC_ERROR_OUT_OF_MEMORY;
        setMessage(function, "out of memory");
    } catch (const std::exception& e) {
        setMessage(function, e.what());
    } catch (...) {
        setMessage(function, "unknown exception");
    }
    return status;
}

void require(bool ok, const std::string& what) {
    if (!ok) throw ArgumentError(what);
}

template <class T>
T& notNull(T* pointer, const char* name) {
    require(pointer != nullptr, std::string(name) + " is NULL");
    return *pointer;
}

const pmsc::Model& modelOf(const pmsc_model* handle) { return *notNull(handle, "model").model; }

/// A buffer and its length: not NULL, and exactly the `expected` elements the call reads or writes.
void requireBuffer(const void* data, const char* name, std::size_t given, std::size_t expected,
                   const char* expectedName) {
    require(data != nullptr, std::string(name) + " is NULL");
    require(given == expected, std::string(name) + " has " + std::to_string(given) + " elements, expected " +
                                   expectedName + " = " + std::to_string(expected));
}

/// Whether two buffers of doubles share memory (compared as addresses, so unrelated buffers are fine).
bool overlap(const double* a, std::size_t aCount, const double* b, std::size_t bCount) {
    const auto begin = [](const double* p) { return reinterpret_cast<std::uintptr_t>(p); };
    return begin(a) < begin(b) + bCount * sizeof(double) && begin(b) < begin(a) + aCount * sizeof(double);
}

void requireApart(const double* in, std::size_t inCount, const double* out, std::size_t outCount,
                  const char* inName, const char* outName) {
    require(!overlap(in, inCount, out, outCount), std::string(outName) + " overlaps " + inName);
}

std::size_t size(pmsc::Index n) { return static_cast<std::size_t>(n); }

std::size_t keyValueCount(const pmsc::Model& m) { return size(m.keyCount() * m.channels); }

const pmsc::Model& modelOf(const pmsc_multiplier& m) { return *m.model.model; }

/// Reads a model with `read` and hands it out as a new handle.
template <class Read>
pmsc_status load(std::string_view function, pmsc_model** out, Read&& read) noexcept {
    if (out != nullptr) *out = nullptr;
    return guarded(function, [&] {
        notNull(out, "model");
        auto handle = std::make_unique<pmsc_model>();
        handle->model = std::make_shared<const pmsc::Model>(read());
        *out = handle.release();
    });
}

pmsc_status create(std::string_view function, const pmsc_model* model, const double* eps,
                   pmsc_multiplier** out) noexcept {
    if (out != nullptr) *out = nullptr;
    return guarded(function, [&] {
        const pmsc::Model& m = modelOf(model);
        notNull(out, "multiplier");
        const pmsc::SoftCachePolicy policy = eps != nullptr ? pmsc::SoftCachePolicy(eps[0], eps[1])
                                                            : pmsc::SoftCachePolicy(m.epsMin, m.epsMax);
        *out = std::make_unique<pmsc_multiplier>(model->model, policy).release();
    });
}

/// One size of a model into *out.
template <class Get>
pmsc_status modelSize(std::string_view function, const pmsc_model* model, std::size_t* out,
                      Get&& get) noexcept {
    return guarded(function, [&] {
        const pmsc::Model& m = modelOf(model);
        notNull(out, "out");
        *out = size(get(m));
    });
}

}  // namespace

// ---- versions, status codes, messages ----------------------------------------------------------

int32_t pmsc_api_version() noexcept { return PMSC_C_API_VERSION; }

const char* pmsc_status_name(pmsc_status status) noexcept {
    switch (status) {
        case PMSC_OK:
            return "ok";
        case PMSC_ERROR_INVALID_ARGUMENT:
            return "invalid argument";
        case PMSC_ERROR_INPUT:
            return "bad input";
        case PMSC_ERROR_OUT_OF_MEMORY:
            return "out of memory";
        case PMSC_ERROR_INTERNAL:
            return "internal error";
        default:
            return "unknown status";
    }
}

const char* pmsc_last_error() noexcept { return tlsMessage; }

// ---- the model ----------------------------------------------------------------------------------

pmsc_status pmsc_model_load(const char* path, pmsc_model** model) noexcept {
    return load(__func__, model, [&] {
        require(path != nullptr, "path is NULL");
        return pmsc::readModel(path);
    });
}

pmsc_status pmsc_model_load_memory(const void* bytes, size_t byte_count, pmsc_model** model) noexcept {
    return load(__func__, model, [&] {
        require(bytes != nullptr, "bytes is NULL");
        return pmsc::decodeModel(std::string_view(static_cast<const char*>(bytes), byte_count),
                                 "model in memory");
    });
}

void pmsc_model_free(pmsc_model* model) noexcept { delete model; }

pmsc_status pmsc_model_point_count(const pmsc_model* model, size_t* points) noexcept {
    return modelSize(__func__, model, points, [](const pmsc::Model& m) { return m.points; });
}

pmsc_status pmsc_model_channel_count(const pmsc_model* model, size_t* channels) noexcept {
    return modelSize(__func__, model, channels, [](const pmsc::Model& m) { return m.channels; });
}

pmsc_status pmsc_model_key_count(const pmsc_model* model, size_t* keys) noexcept {
    return modelSize(__func__, model, keys, [](const pmsc::Model& m) { return m.keyCount(); });
}

pmsc_status pmsc_model_basis_size(const pmsc_model* model, size_t* basis_size) noexcept {
    return modelSize(__func__, model, basis_size, [](const pmsc::Model& m) { return m.basisSize(); });
}

pmsc_status pmsc_model_coord_count(const pmsc_model* model, size_t* coords) noexcept {
    return modelSize(__func__, model, coords, [](const pmsc::Model& m) { return m.coordCount(); });
}

pmsc_status pmsc_model_region_count(const pmsc_model* model, size_t* regions) noexcept {
    return modelSize(__func__, model, regions, [](const pmsc::Model& m) {
        return m.regions ? m.regions->regionCount() : pmsc::Index{0};
    });
}

pmsc_status pmsc_model_key_points(const pmsc_model* model, int64_t* key_points,
                                  size_t key_point_count) noexcept {
    return guarded(__func__, [&] {
        const pmsc::Model& m = modelOf(model);
        requireBuffer(key_points, "key_points", key_point_count, size(m.keyCount()), "K");
        for (std::size_t i = 0; i < key_point_count; ++i)
            key_points[i] = static_cast<int64_t>(m.keyPoints[i]);
    });
}

pmsc_status pmsc_model_sentinel_count(const pmsc_model* model, size_t* count) noexcept {
    return guarded(__func__, [&] {
        const pmsc::Model& m = modelOf(model);
        notNull(count, "count") = m.sentinels ? m.sentinels->points.size() : 0;
    });
}

pmsc_status pmsc_model_sentinels(const pmsc_model* model, int64_t* sentinels, size_t count) noexcept {
    return guarded(__func__, [&] {
        const pmsc::Model& m = modelOf(model);
        const std::size_t s = m.sentinels ? m.sentinels->points.size() : 0;
        if (s == 0 && count == 0) return;
        requireBuffer(sentinels, "sentinels", count, s, "S");
        for (std::size_t i = 0; i < count; ++i) sentinels[i] = static_cast<int64_t>(m.sentinels->points[i]);
    });
}

pmsc_status pmsc_model_eps(const pmsc_model* model, double* eps_min, double* eps_max) noexcept {
    return guarded(__func__, [&] {
        const pmsc::Model& m = modelOf(model);
        notNull(eps_min, "eps_min") = m.epsMin;
        notNull(eps_max, "eps_max") = m.epsMax;
    });
}

// ---- the runtime --------------------------------------------------------------------------------

pmsc_status pmsc_multiplier_create(const pmsc_model* model, pmsc_multiplier** multiplier) noexcept {
    return create(__func__, model, nullptr, multiplier);
}

pmsc_status pmsc_multiplier_create_with_eps(const pmsc_model* model, double eps_min, double eps_max,
                                            pmsc_multiplier** multiplier) noexcept {
    const double eps[2] = {eps_min, eps_max};
    return create(__func__, model, eps, multiplier);
}

void pmsc_multiplier_free(pmsc_multiplier* multiplier) noexcept { delete multiplier; }

pmsc_status pmsc_multiplier_model(const pmsc_multiplier* multiplier, const pmsc_model** model) noexcept {
    if (model != nullptr) *model = nullptr;
    return guarded(__func__, [&] {
        const pmsc_multiplier& m = notNull(multiplier, "multiplier");
        notNull(model, "model") = &m.model;
    });
}

pmsc_status pmsc_multiplier_eps(const pmsc_multiplier* multiplier, double* eps_min,
                                double* eps_max) noexcept {
    return guarded(__func__, [&] {
        const pmsc_multiplier& m = notNull(multiplier, "multiplier");
        notNull(eps_min, "eps_min") = m.policy.epsMin();
        notNull(eps_max, "eps_max") = m.policy.epsMax();
    });
}

pmsc_status pmsc_multiplier_project(const pmsc_multiplier* multiplier, const double* key_values,
                                    size_t key_value_count, double* coords, size_t coord_count) noexcept {
    return guarded(__func__, [&] {
        const pmsc_multiplier& m = notNull(multiplier, "multiplier");
        requireBuffer(key_values, "key_values", key_value_count, keyValueCount(modelOf(m)), "K*C");
        requireBuffer(coords, "coords", coord_count, size(modelOf(m).coordCount()), "the coordinate count");
        requireApart(key_values, key_value_count, coords, coord_count, "key_values", "coords");
        m.multiplier.project(key_values, coords);
    });
}

pmsc_status pmsc_multiplier_key_error(const pmsc_multiplier* multiplier, const double* key_values,
                                      size_t key_value_count, const double* coords, size_t coord_count,
                                      double* key_error) noexcept {
    return guarded(__func__, [&] {
        const pmsc_multiplier& m = notNull(multiplier, "multiplier");
        requireBuffer(key_values, "key_values", key_value_count, keyValueCount(modelOf(m)), "K*C");
        requireBuffer(coords, "coords", coord_count, size(modelOf(m).coordCount()), "the coordinate count");
        notNull(key_error, "key_error") = m.multiplier.keyError(key_values, coords);
    });
}

pmsc_status pmsc_multiplier_decide(const pmsc_multiplier* multiplier, double key_error,
                                   pmsc_decision* decision) noexcept {
    return guarded(__func__, [&] {
        const pmsc_multiplier& m = notNull(multiplier, "multiplier");
        const pmsc::CacheDecision d = m.policy.decide(key_error);
        notNull(decision, "decision") = pmsc_decision{static_cast<pmsc_cache_state>(d.state), d.weight};
    });
}

pmsc_status pmsc_multiplier_reconstruct(const pmsc_multiplier* multiplier, const double* coords,
                                        size_t coord_count, double* out, size_t out_count) noexcept {
    return guarded(__func__, [&] {
        const pmsc_multiplier& m = notNull(multiplier, "multiplier");
        const pmsc::Model& model = modelOf(m);
        requireBuffer(coords, "coords", coord_count, size(model.coordCount()), "the coordinate count");
        requireBuffer(out, "out", out_count, size(model.points * model.channels), "N*C");
        requireApart(coords, coord_count, out, out_count, "coords", "out");
        m.multiplier.reconstruct(coords, out);
    });
}

pmsc_status pmsc_multiplier_reconstruct_points(const pmsc_multiplier* multiplier, const double* coords,
                                               size_t coord_count, const int64_t* points, size_t point_count,
                                               double* out, size_t out_count) noexcept {
    return guarded(__func__, [&] {
        const pmsc_multiplier& m = notNull(multiplier, "multiplier");
        const pmsc::Model& model = modelOf(m);
        requireBuffer(coords, "coords", coord_count, size(model.coordCount()), "the coordinate count");
        if (point_count == 0) return;
        require(points != nullptr, "points is NULL");
        requireBuffer(out, "out", out_count, point_count * size(model.channels), "point_count*C");
        requireApart(coords, coord_count, out, out_count, "coords", "out");
        for (std::size_t i = 0; i < point_count; ++i) {
            require(points[i] >= 0 && points[i] < model.points,
                    "points[" + std::to_string(i) + "] = " + std::to_string(points[i]) + " is outside [0, " +
                        std::to_string(model.points) + ")");
        }
        if constexpr (std::is_same_v<pmsc::Index, int64_t>) {
            m.multiplier.reconstructPoints(coords, std::span<const pmsc::Index>(points, point_count), out);
        } else {
            const std::vector<pmsc::Index> copy(points, points + point_count);
            m.multiplier.reconstructPoints(coords, copy, out);
        }
    });
}

pmsc_status pmsc_multiplier_check_sentinels(const pmsc_multiplier* multiplier, const double* coords,
                                            size_t coord_count, const double* values, size_t value_count,
                                            int* stands) noexcept {
    return guarded(__func__, [&] {
        const pmsc_multiplier& m = notNull(multiplier, "multiplier");
        const pmsc::Model& model = modelOf(m);
        int& result = notNull(stands, "stands");
        requireBuffer(coords, "coords", coord_count, size(model.coordCount()), "the coordinate count");
        const std::size_t s = model.sentinels ? model.sentinels->points.size() : 0;
        result = 1;
        if (s == 0 && value_count == 0) return;
        requireBuffer(values, "values", value_count, s * size(model.channels), "S*C");
        requireApart(coords, coord_count, values, value_count, "coords", "values");
        result = m.check.passes(coords, model.sentinels->points, values) ? 1 : 0;
    });
}

namespace {
/// A blend's checks: the weight in [0, 1], and for count > 0 three buffers, out apart from pm and
/// full unless it is one of them. False when there is nothing to blend (count 0).
bool blendBuffersUsable(double weight, const double* pm, const double* full, const double* out,
                        size_t count) {
    require(weight >= 0 && weight <= 1, "weight " + std::to_string(weight) + " is not in [0, 1]");
    if (count == 0) return false;
    notNull(pm, "pm");
    notNull(full, "full");
    notNull(out, "out");
    if (out != pm) requireApart(pm, count, out, count, "pm", "out");
    if (out != full) requireApart(full, count, out, count, "full", "out");
    return true;
}
}  // namespace

pmsc_status pmsc_multiplier_blend(const pmsc_multiplier* multiplier, double weight, const double* pm,
                                  const double* full, double* out, size_t count) noexcept {
    return guarded(__func__, [&] {
        const pmsc::Model& model = modelOf(notNull(multiplier, "multiplier"));
        const size_t c = size(model.channels);
        require(count % c == 0,
                "count " + std::to_string(count) + " is not a multiple of C = " + std::to_string(c));
        if (!blendBuffersUsable(weight, pm, full, out, count)) return;
        pmsc::blendPoints(weight, model.tolerance, model.channels, pm, full, out, pmsc::Index(count / c));
    });
}

pmsc_status pmsc_blend(double weight, const double* pm, const double* full, double* out,
                       size_t count) noexcept {
    return guarded(__func__, [&] {
        if (!blendBuffersUsable(weight, pm, full, out, count)) return;
        for (std::size_t i = 0; i < count; ++i) out[i] = (1.0 - weight) * pm[i] + weight * full[i];
    });
}
