// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/PointEvaluator.h"

#include <nlohmann/json.hpp>

#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace pmsc::viewer {

/// One control a lighter moves (a slider of the page): the light's azimuth, its colour
/// temperature, ...
struct Control {
    std::string name;   ///< key of Controls
    std::string label;  ///< shown by the page
    std::string unit;
    double min = 0, max = 1, step = 0.1, value = 0;  ///< range and default
};

/// Values of a scene's controls by name.
using Controls = std::map<std::string, double>;

/// A scene an interactive viewer relights: its points laid out in a dense box of voxels (what the
/// page uploads as a 3D texture), its controls, and for any setting of them the full calculation
/// of its points as a one-frame PointEvaluator. Implementations: the volume (any .vdb density)
/// and the Cornell box. Thread safety: const methods may run concurrently.
class RelightScene {
public:
    virtual ~RelightScene() = default;

    virtual std::string kind() const = 0;  ///< "volume" or "cornell"
    virtual Index pointCount() const = 0;
    virtual const std::vector<Control>& controls() const = 0;
    /// The scene for the page: kind, source, points, grid, light, camera and the kind's own
    /// fields (docs/viewer.md). `controls`, `model` and `light` are added by the server.
    virtual nlohmann::json describe() const = 0;
    /// Little-endian bytes: N uint32 dense indices i + nx (j + ny k), then the kind's per-point
    /// data (volume: N float32 densities; cornell: N x 3 float32 normals).
    virtual std::string geometry() const = 0;
    /// The light the controls make: {"position": [x, y, z], "radius": r}.
    virtual nlohmann::json light(const Controls& controls) const = 0;
    /// The full calculation of every point for these controls (one frame, frame 0).
    /// @throws pmsc::InputError for a value outside its control's range or an unknown name.
    virtual std::shared_ptr<const PointEvaluator> evaluator(const Controls& controls) const = 0;

    /// The default value of every control.
    Controls defaults() const;
    /// `given` over the defaults, each value checked against its control's range.
    /// @throws pmsc::InputError (one line) for an unknown name, a non-finite value or one out of range.
    Controls resolve(const Controls& given) const;
};

/// The scene of a spec: "volume:FILE.vdb[:grid=NAME][:samples=S]" or "cornell[:points=N,samples=S]"
/// (the same options as the `volume` and `cornell` evaluators; a `lights=` option is refused,
/// the viewer's lights come from its controls).
/// @throws pmsc::InputError for a bad spec or file (one line).
std::unique_ptr<RelightScene> makeRelightScene(const std::string& spec);

/// Points in a dense box of voxels: the box's size and each point's index i + nx (j + ny k),
/// from positions that lie on a grid of spacing `voxel` (rounded to the nearest node).
struct DenseLayout {
    std::int64_t dims[3] = {0, 0, 0};
    double origin[3] = {0, 0, 0};  ///< world position of voxel (0, 0, 0)'s centre
    double voxel = 0;
    std::vector<std::uint32_t> index;

    static DenseLayout of(const std::vector<std::array<double, 3>>& positions, double voxel);
    nlohmann::json toJson() const;
};

}  // namespace pmsc::viewer
