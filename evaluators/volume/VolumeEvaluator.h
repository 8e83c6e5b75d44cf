// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/volume/DensityVolume.h"
#include "pmsc/FrameWriter.h"
#include "pmsc/PointEvaluator.h"
#include "pmsc/PointPositions.h"

#include <memory>
#include <string>
#include <vector>

namespace pmsc::volume {

/// The optical properties of the medium and the accuracy of the calculation.
struct MediumSettings {
    /// Extinction coefficient per unit density, per world unit. 0 = automatic: 16 / the longest
    /// side of the active voxels' bounds (the demo's 4 m smoke: 4 per metre, so a densest
    /// voxel's mean free path is a quarter metre and the optical depth through the middle of the
    /// lumpy smoke is 2 to 4: a lit side, a shadowed side, light that still gets through).
    double sigmaT = 0;
    /// Single-scattering albedo, RGB: a slightly blue-white smoke (higher orders of scattering
    /// carry albedo^k, so the shadowed side, lit by multiple scattering, turns bluer).
    Rgb albedo{0.90, 0.93, 0.97};
    /// Shadow rays per voxel to the spherical light (stratified on its disk): soft shadows.
    int lightSamples = 6;
    /// March step of the shadow rays, in voxels (midpoint rule inside each active leaf span).
    double stepVoxels = 1.0;
    /// Multiple scattering: this many octaves beyond single scattering (0 = single only), after
    /// Wrenninge, Kulla and Lundqvist, "Oz: The Great and Volumetric" (SIGGRAPH 2013 talk): order
    /// k is single scattering through an extinction scaled by a^k with the scattering scaled by
    /// (b albedo)^k; it reuses each shadow ray's optical depth, so it costs no extra rays.
    int octaves = 3;
    double octaveExtinction = 0.4;  ///< a: deeper orders see a more transparent medium
    double octaveScattering = 0.6;  ///< b: and carry less energy
};

/// A spherical light: position, radius (world units), colour temperature and RGB radiant
/// intensity (W/sr; the rig scales it so an unshadowed voxel at the medium's centre receives an
/// irradiance of 1 in luminance).
struct VolumeLight {
    Vec3 position;
    double radius = 0;
    double kelvin = 6500;
    Rgb intensity{0, 0, 0};
};

/// RGB of a black body at `kelvin` (Planck's law sampled at 610, 550 and 465 nm), scaled to a
/// luminance (Rec. 709 weights) of 1. @throws std::invalid_argument outside [1000, 40000] K.
Rgb kelvinToRgb(double kelvin);

/// The medium and what every evaluator of a run shares.
struct VolumeWorld {
    DensityVolume density;
    MediumSettings medium;  ///< sigmaT resolved (never 0)
    Vec3 centre;            ///< of the active voxels' bounds
    double radius = 0;      ///< half the bounds' diagonal
    std::string source;     ///< file or mesh it came from (for reports)

    static std::shared_ptr<const VolumeWorld> create(DensityVolume density, MediumSettings medium,
                                                     std::string source);
};

/// The light rig: a spherical light on a sphere of radius distance x world.radius around the
/// medium's centre, moving in azimuth (around) and elevation (over), with its colour temperature
/// as the second control. Angles in degrees, elevation from the horizontal (y up).
struct VolumeRig {
    int azimuths = 16;  ///< training azimuth steps over 360 degrees
    /// Training elevations: 14 degrees apart (measured at 60,000 voxels, M = 48: with 4 elevations
    /// 24 degrees apart the validation frames are 1.11% from the span of the basis, with these 6
    /// 0.93%; the elevation step, not the azimuth step, is what limits it).
    std::vector<double> elevations{6, 20, 34, 48, 62, 76};
    /// Training colours (a warm and a cool stage light). Why not 3000-8000 K: colour enters as an RGB
    /// factor, and a colour temperature between two training ones is not a combination of their
    /// RGB (the black-body locus curves): 2.8% of it lies outside their plane for 3000/8000 K,
    /// which PMSC cannot reconstruct (measured 3.0% RMS error at 60,000 voxels); for 4000/6500 K
    /// it is at most 0.7%.
    double kelvinLow = 4000, kelvinHigh = 6500;
    /// false: the two colours alternate over the positions like a chessboard (96 frames); true:
    /// every position in both colours (192 frames, the second by recolour()).
    bool colourPairs = false;
    /// > 0: instead of the azimuth x elevation grid, this many training positions on a spiral
    /// (golden-angle azimuths, even in area) over the band of elevations [elevations.front(),
    /// elevations.back()]: the same spacing everywhere, where the grid crowds its positions
    /// together near the top. Colours then cycle through `colours` temperatures from kelvinLow to
    /// kelvinHigh along the spiral (neighbours on the sphere get different ones).
    int spiral = 0;
    /// Training colour temperatures of the spiral, evenly from kelvinLow to kelvinHigh: 2 spans the
    /// plane of two black-body RGBs; 3 also holds the locus's curvature between them.
    int colours = 2;
    double distance = 2.0;      ///< x world.radius
    double lightRadius = 0.45;  ///< x world.radius (a soft light: 13 degrees across from the rig)

    VolumeLight light(const VolumeWorld& world, double azimuthDeg, double elevationDeg, double kelvin) const;
    /// azimuths x elevations frames (96 by default; x 2 with colourPairs: kelvinLow then kelvinHigh at each
    /// position), elevation-major.
    std::vector<VolumeLight> training(const VolumeWorld& world) const;
    /// `count` settings between the training ones, colour temperatures between kelvinLow and
    /// kelvinHigh (fixed seed). Grid: half a step off in azimuth and in elevation. Spiral: the
    /// holes of the training set: among 4,096 random candidates in the band, repeatedly the one
    /// farthest from every training position and every hole already taken.
    std::vector<VolumeLight> between(const VolumeWorld& world, int count) const;
    /// The training positions' directions from the medium's centre (unit vectors), as training().
    std::vector<Vec3> trainingDirections() const;
    /// An animation: one turn around the medium while rising and sinking between the lowest and
    /// highest training elevation, the colour temperature swinging between the training ones.
    std::vector<VolumeLight> path(const VolumeWorld& world, int frames) const;
    /// 24 lights outside the trained range, for testing what the soft cache does with light it
    /// never saw: 12 below the band of training elevations (20 and 45 degrees under its lowest,
    /// six azimuths each), 8 in colours outside [kelvinLow, kelvinHigh] (2700 K and 12000 K at the
    /// band's middle, four azimuths each), and 4 closer to the medium (1.3 x its radius instead of
    /// `distance`, so nearer voxels brighten faster than far ones).
    std::vector<VolumeLight> outside(const VolumeWorld& world) const;

    /// How far the light at the centre of a training grid cell is from the mean of the cell's four
    /// corner lights (relative RMS over a sample of voxels and cells, full calculation, one colour):
    /// how fast this medium's lighting changes at this rig's spacing, which is what a basis of the
    /// training frames has to interpolate. Grid rigs only (spiral: 0).
    double cellInterpolationError(const VolumeWorld& world) const;

    /// The rig for a medium: `base` (the default 16 x 6 grid) refined over the same band of
    /// elevations, azimuth and elevation steps shrinking together (20 x 7, 24 x 8, 28 x 9, 32 x 11),
    /// until its cellInterpolationError is at most kCellErrorGoal. A spiral base is returned as
    /// it is. Deterministic for a medium; each grid tried costs 5 x 24 lights at 512 voxels, 61,440
    /// voxel calculations (0.42 of a full frame of the 145,883-voxel spider; 2.3 to 2.6 s per grid
    /// on a shared 2-core machine).
    static VolumeRig forMedium(const VolumeWorld& world, const VolumeRig& base);
    static VolumeRig forMedium(const VolumeWorld& world);  ///< from the default rig
    /// The goal of forMedium: the demo's smoke (Wuson, 253,972 voxels) gives 0.0163 at 16 x 6, where
    /// its reference ratio is 1.34 (goal 1.5); a uniform spider 0.0245 and a uniform dodecahedron
    /// 0.0299 there, 0.014 and 0.015 at 24 x 8 (docs/volume.md, "Other media").
    static constexpr double kCellErrorGoal = 0.017;
};

/// Values of a frame lit by `to` from those of a frame lit by `from`, when the two lights differ in
/// colour only: transport is linear in the light's RGB intensity, so each channel scales by
/// to.intensity / from.intensity (exact up to rounding). The demo computes each training position
/// once and gets its second colour this way; the point multiplication never uses it (it knows
/// nothing about lights). @throws std::invalid_argument if position or radius differ.
void recolour(const VolumeLight& from, const VolumeLight& to, double* values, Index points);

/// The full calculation per active voxel: the in-scattered radiance (RGB, isotropic
/// phase 1/4pi, so view-independent) from the frame's spherical light,
///   L(x) = I / (4 pi d^2) x mean_j [ T_j + sum_k (b albedo)^k T_j^(a^k) ],
///   T_j = exp(-sigma_t integral density) along the shadow ray from x to the j-th point on the light,
/// with S = lightSamples shadow rays stratified on the light's disk (a shifted Hammersley set
/// that depends on the voxel only: the same pattern every frame, so the remaining noise is a
/// fixed per-voxel pattern like the Cornell gather's) and the octave approximation of multiple
/// scattering (MediumSettings::octaves).
///
/// Transmittance by a ray march, not ratio or delta tracking: a march is deterministic and
/// noise-free for a given step, and the density is itself trilinear data, so the midpoint rule
/// at one voxel per step is within 0.5% of a four-times finer march (tested); tracking estimators
/// would add per-frame noise that no basis can represent. OpenVDB's VolumeRayIntersector skips
/// the empty space between the medium and the light.
///
/// Deterministic: a voxel's value depends on its index and the frame only (bit-identical alone,
/// among all voxels, at any thread count). evaluate() is serial and thread-safe (a Tracer per
/// call); evaluateAll() runs tbb::parallel_for in the caller's arena.
///
/// A FrameWriterProvider: `pmsc run --format vdb` writes each frame as a ScatterCache .vdb.
class VolumeEvaluator : public PointEvaluator, public FrameWriterProvider, public PointPositionsProvider {
public:
    VolumeEvaluator(std::shared_ptr<const VolumeWorld> world, std::vector<VolumeLight> lights,
                    std::string name = "volume");

    std::string name() const override { return name_; }
    Index pointCount() const override { return static_cast<Index>(world_->density.voxelCount()); }
    Index channelCount() const override { return 3; }
    Index frameCount() const override { return static_cast<Index>(lights_.size()); }
    void evaluate(Index frame, std::span<const Index> points, double* out) const override;
    void evaluateAll(Index frame, double* out) const override;
    std::vector<std::shared_ptr<const FrameWriter>> frameWriters() const override;
    /// The active voxels' centres in world units.
    FrameSet pointPositions() const override;

    const VolumeWorld& world() const { return *world_; }
    const std::vector<VolumeLight>& lights() const { return lights_; }
    /// The cache file's metadata for a frame.
    ScatterCacheInfo info(Index frame, std::string state) const;

private:
    void scatter(const VolumeLight& light, Index point, DensityVolume::Tracer& tracer, double* rgb) const;

    std::shared_ptr<const VolumeWorld> world_;
    std::vector<VolumeLight> lights_;
    std::string name_;
};

/// The parts of a `volume:` spec "FILE.vdb[:grid=NAME][:samples=S][:lights=SET]" (options are the
/// trailing ':'-separated items that contain '='). @throws pmsc::InputError for a bad option.
struct VolumeSpec {
    std::string path;
    std::string grid;            ///< empty: the file's density grid (DensityVolume::read)
    std::string lights = "all";  ///< all, training, between, path or outside
    MediumSettings medium;
};
VolumeSpec parseVolumeSpec(const std::string& args);

/// The `volume` evaluator of the command line: ARGS = "FILE.vdb[:grid=NAME][:samples=S]
/// [:lights=all|training|between|path|outside]". lights=all (default): the training lights of
/// VolumeRig::forMedium (96 for the demo's smoke, more for a medium whose lighting changes faster
/// with the light's direction), then 16 lights between them, then a 48-frame path (the demo's
/// frames, so export-frames and run share one spec); outside: VolumeRig::outside's 24 lights, not
/// part of all. @throws pmsc::InputError for a bad option or
/// file (one line).
std::unique_ptr<VolumeEvaluator> makeVolumeEvaluator(const std::string& args);

}  // namespace pmsc::volume
