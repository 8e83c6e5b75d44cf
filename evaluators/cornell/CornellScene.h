// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/scene/Geometry.h"

#include <array>
#include <string>
#include <vector>

namespace pmsc::cornell {

using scene::Camera;
using scene::cross;
using scene::dot;
using scene::length;
using scene::normalize;
using scene::Rgb;
using scene::Vec3;

/// One planar quad of the box, corners in order, with its diffuse reflectance and the
/// unit normal of its visible side.
struct Quad {
    std::string name;
    std::array<Vec3, 4> corners;
    Rgb albedo;
    Vec3 normal;  ///< unit, pointing to the side the box's light reaches
    double area() const;
    /// Closest point of the quad to p, on the two triangles Embree traces (0-1-3 and 2-3-1).
    Vec3 closestPoint(Vec3 p) const;
};

/// The measured Cornell box (shared/data/cornell-box.md), millimetres, y up.
///
/// Decisions the data leaves open:
/// - The light opening in the ceiling is closed: the paper's experiment lights the box with one
///   point light per frame (section 8), not the original area light, so the ceiling is whole.
/// - Normals: walls face the box's centre, block faces face away from their block's centre.
/// - The floor under the blocks is kept in the geometry (the ray tracer needs it), but
///   surfaces inside a block are never points of the lighting cache (see SurfaceVoxels).
class CornellScene {
public:
    /// The box exactly as measured: 5 walls, 5 quads per block.
    static CornellScene standard();

    const std::vector<Quad>& quads() const { return quads_; }
    double totalArea() const;
    /// True if p lies strictly inside one of the two blocks (their footprint, below their top).
    bool insideBlock(Vec3 p, double marginMm = 0) const;

    /// This scene with an axis-aligned box [lo, hi] (mm) added: white, its faces' normals pointing
    /// out; no bottom face when it stands on the floor (lo.y <= 0), whose floor it covers. Its quads
    /// come after this scene's, so every quad index of this scene (SurfaceVoxels::quad) keeps its
    /// meaning. Not a block for insideBlock(): it is a change of the lit scene (the demo's local
    /// change), while the cache's points stay those voxelized without it.
    /// @throws std::invalid_argument unless lo < hi in every axis.
    CornellScene withBox(const std::string& name, Vec3 lo, Vec3 hi) const;

    /// The measured camera: (278, 273, -800) looking down +z, 39.3077 degrees.
    static Camera standardCamera();

private:
    std::vector<Quad> quads_;
    struct Block {
        std::array<Vec3, 4> footprint;  // top quad's corners projected to y = 0 (xz)
        double height;
    };
    std::vector<Block> blocks_;
};

/// A point light: position in millimetres and RGB intensity (power per steradian).
struct PointLight {
    Vec3 position;
    Rgb intensity;
};

/// The light positions of the experiment (section 8). Distances in millimetres.
struct LightRig {
    int gridSide = 12;                     ///< 12 x 12 = 144 training lights
    double spacingMm = 36.0;               ///< grid pitch in x and z
    double belowCeilingMm = 60.0;          ///< lights at y = 548.8 - this
    Rgb intensity{1.6e5, 1.36e5, 1.12e5};  ///< warm white, gives irradiance of order 1

    /// The 12 x 12 training grid, row-major in (z, x), centred on the ceiling.
    std::vector<PointLight> trainingLights() const;
    /// `count` lights near the training grid but never on it: jittered off the grid nodes by
    /// 15-85% of the pitch in x and z and up to 4 mm in y (deterministic for a seed).
    std::vector<PointLight> scatteredLights(int count, unsigned seed = 7) const;
    /// A smooth closed `frames`-frame path (a Lissajous figure) across the grid's extent.
    std::vector<PointLight> animationPath(int frames) const;
    /// 24 lights outside the trained range, for testing what the soft cache does with light it
    /// never saw: 12 lower in the box (120, 220 and 320 mm under the training plane, at four
    /// places clear of the blocks), 8 beyond the grid's extent at its height (the four corners
    /// and four wall midpoints, 30 mm from the walls), and 4 on the grid's plane in a cool white
    /// (another RGB ratio than the training's).
    std::vector<PointLight> outsideLights() const;
};

/// Cameras of the moving-camera renders: the standard view, an orbit outside the opening
/// and one inside the box. `t` in [0, 1] moves each along its own path.
std::vector<Camera> demoCameras(double t);

}  // namespace pmsc::cornell
