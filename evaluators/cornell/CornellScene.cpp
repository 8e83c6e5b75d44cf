#include "evaluators/cornell/CornellScene.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

namespace pmsc::cornell {

double Quad::area() const {
    const Vec3 a = cross(corners[1] - corners[0], corners[2] - corners[0]);
    const Vec3 b = cross(corners[2] - corners[0], corners[3] - corners[0]);
    return 0.5 * (length(a) + length(b));
}

namespace {

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5).
Vec3 closestOnTriangle(Vec3 p, Vec3 a, Vec3 b, Vec3 c) {
    const Vec3 ab = b - a, ac = c - a, ap = p - a;
    const double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return a;
    const Vec3 bp = p - b;
    const double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return b;
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + ab * (d1 / (d1 - d3));
    const Vec3 cp = p - c;
    const double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return c;
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + ac * (d2 / (d2 - d6));
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0)
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    const double denom = 1.0 / (va + vb + vc);
    return a + ab * (vb * denom) + ac * (vc * denom);
}

Vec3 v(double x, double y, double z) { return {x, y, z}; }

constexpr Rgb kWhite{0.886, 0.699, 0.666};
constexpr Rgb kRed{0.570, 0.043, 0.044};
constexpr Rgb kGreen{0.105, 0.378, 0.076};

// Orients the quad's normal toward `towards` (walls) or away from `awayFrom` (blocks).
Quad makeQuad(std::string name, std::array<Vec3, 4> c, Rgb albedo, Vec3 reference, bool facing) {
    Vec3 n = normalize(cross(c[1] - c[0], c[2] - c[0]));
    const Vec3 centre = (c[0] + c[1] + c[2] + c[3]) * 0.25;
    const double side = dot(reference - centre, n);
    if ((facing && side < 0) || (!facing && side > 0)) n = n * -1.0;
    return {std::move(name), c, albedo, n};
}

// Point-in-convex-polygon test in the xz plane.
bool insideXz(const std::array<Vec3, 4>& poly, double x, double z, double margin) {
    double sign = 0;
    for (int i = 0; i < 4; ++i) {
        const Vec3 a = poly[i], b = poly[(i + 1) % 4];
        const double ex = b.x - a.x, ez = b.z - a.z;
        const double len = std::hypot(ex, ez);
        const double s = (ex * (z - a.z) - ez * (x - a.x)) / len;  // signed distance to edge
        if (sign == 0) sign = s > 0 ? 1 : -1;
        if (s * sign < margin) return false;
    }
    return true;
}

}  // namespace

Vec3 Quad::closestPoint(Vec3 p) const {
    // The same two triangles Embree makes of a quad (v0 v1 v3 and v2 v3 v1): the measured left
    // wall is not planar (its corners bend by about a millimetre), and a gather point on the
    // other diagonal's triangles would sit behind the surface Embree traces, so every gather
    // ray would leave through the wall's back face.
    const Vec3 a = closestOnTriangle(p, corners[0], corners[1], corners[3]);
    const Vec3 b = closestOnTriangle(p, corners[2], corners[3], corners[1]);
    return dot(a - p, a - p) <= dot(b - p, b - p) ? a : b;
}

CornellScene CornellScene::standard() {
    CornellScene s;
    const Vec3 roomCentre = v(278, 274.4, 279.6);
    auto wall = [&](std::string n, std::array<Vec3, 4> c, Rgb a) {
        s.quads_.push_back(makeQuad(std::move(n), c, a, roomCentre, true));
    };
    wall("floor", {v(552.8, 0, 0), v(0, 0, 0), v(0, 0, 559.2), v(549.6, 0, 559.2)}, kWhite);
    wall("ceiling", {v(556, 548.8, 0), v(556, 548.8, 559.2), v(0, 548.8, 559.2), v(0, 548.8, 0)}, kWhite);
    wall("back", {v(549.6, 0, 559.2), v(0, 0, 559.2), v(0, 548.8, 559.2), v(556, 548.8, 559.2)}, kWhite);
    wall("left", {v(552.8, 0, 0), v(549.6, 0, 559.2), v(556, 548.8, 559.2), v(556, 548.8, 0)}, kRed);
    wall("right", {v(0, 0, 559.2), v(0, 0, 0), v(0, 548.8, 0), v(0, 548.8, 559.2)}, kGreen);

    auto block = [&](const std::string& n, std::array<Vec3, 4> top,
                     std::array<std::array<Vec3, 4>, 4> sides) {
        Vec3 centre{};
        for (const Vec3& c : top) centre = centre + c * 0.25;
        centre.y *= 0.5;
        s.quads_.push_back(makeQuad(n + " top", top, kWhite, centre, false));
        for (int i = 0; i < 4; ++i)
            s.quads_.push_back(makeQuad(n + " side " + std::to_string(i), sides[i], kWhite, centre, false));
        Block b;
        for (int i = 0; i < 4; ++i) b.footprint[i] = v(top[i].x, 0, top[i].z);
        b.height = top[0].y;
        s.blocks_.push_back(b);
    };
    block("short block", {v(130, 165, 65), v(82, 165, 225), v(240, 165, 272), v(290, 165, 114)},
          {{{v(290, 0, 114), v(290, 165, 114), v(240, 165, 272), v(240, 0, 272)},
            {v(130, 0, 65), v(130, 165, 65), v(290, 165, 114), v(290, 0, 114)},
            {v(82, 0, 225), v(82, 165, 225), v(130, 165, 65), v(130, 0, 65)},
            {v(240, 0, 272), v(240, 165, 272), v(82, 165, 225), v(82, 0, 225)}}});
    block("tall block", {v(423, 330, 247), v(265, 330, 296), v(314, 330, 456), v(472, 330, 406)},
          {{{v(423, 0, 247), v(423, 330, 247), v(472, 330, 406), v(472, 0, 406)},
            {v(472, 0, 406), v(472, 330, 406), v(314, 330, 456), v(314, 0, 456)},
            {v(314, 0, 456), v(314, 330, 456), v(265, 330, 296), v(265, 0, 296)},
            {v(265, 0, 296), v(265, 330, 296), v(423, 330, 247), v(423, 0, 247)}}});
    return s;
}

CornellScene CornellScene::withBox(const std::string& name, Vec3 lo, Vec3 hi) const {
    if (!(lo.x < hi.x && lo.y < hi.y && lo.z < hi.z))
        throw std::invalid_argument("CornellScene::withBox: '" + name + "' needs lo < hi in x, y and z");
    CornellScene s = *this;
    const Vec3 centre = (lo + hi) * 0.5;
    auto face = [&](const std::string& side, std::array<Vec3, 4> c) {
        s.quads_.push_back(makeQuad(name + " " + side, c, kWhite, centre, false));
    };
    const double x0 = lo.x, y0 = lo.y, z0 = lo.z, x1 = hi.x, y1 = hi.y, z1 = hi.z;
    face("top", {v(x0, y1, z0), v(x1, y1, z0), v(x1, y1, z1), v(x0, y1, z1)});
    face("front", {v(x0, y0, z0), v(x1, y0, z0), v(x1, y1, z0), v(x0, y1, z0)});
    face("back", {v(x0, y0, z1), v(x0, y1, z1), v(x1, y1, z1), v(x1, y0, z1)});
    face("left", {v(x1, y0, z0), v(x1, y0, z1), v(x1, y1, z1), v(x1, y1, z0)});
    face("right", {v(x0, y0, z0), v(x0, y1, z0), v(x0, y1, z1), v(x0, y0, z1)});
    if (lo.y > 0) face("bottom", {v(x0, y0, z0), v(x0, y0, z1), v(x1, y0, z1), v(x1, y0, z0)});
    return s;
}

double CornellScene::totalArea() const {
    double a = 0;
    for (const Quad& q : quads_) a += q.area();
    return a;
}

bool CornellScene::insideBlock(Vec3 p, double marginMm) const {
    for (const Block& b : blocks_) {
        if (p.y < b.height - marginMm && insideXz(b.footprint, p.x, p.z, marginMm)) return true;
    }
    return false;
}

Camera CornellScene::standardCamera() {
    return {"standard", v(278, 273, -800), v(278, 273, -799), v(0, 1, 0), 39.3077};
}

std::vector<PointLight> LightRig::trainingLights() const {
    std::vector<PointLight> lights;
    const double y = 548.8 - belowCeilingMm;
    for (int iz = 0; iz < gridSide; ++iz) {
        for (int ix = 0; ix < gridSide; ++ix) {
            const double x = 278.0 + (ix - 0.5 * (gridSide - 1)) * spacingMm;
            const double z = 279.6 + (iz - 0.5 * (gridSide - 1)) * spacingMm;
            lights.push_back({v(x, y, z), intensity});
        }
    }
    return lights;
}

std::vector<PointLight> LightRig::scatteredLights(int count, unsigned seed) const {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::uniform_int_distribution<int> cell(0, gridSide - 2);
    std::vector<PointLight> lights;
    const double y = 548.8 - belowCeilingMm;
    for (int i = 0; i < count; ++i) {
        // Between two grid nodes in both x and z: at least 15% of the pitch off any node.
        const auto off = [&] { return spacingMm * (0.15 + 0.7 * u01(rng)); };
        const double x = 278.0 + (cell(rng) - 0.5 * (gridSide - 1)) * spacingMm + off();
        const double z = 279.6 + (cell(rng) - 0.5 * (gridSide - 1)) * spacingMm + off();
        const double dy = -4.0 + 8.0 * u01(rng);
        lights.push_back({v(x, y + dy, z), intensity});
    }
    return lights;
}

std::vector<PointLight> LightRig::animationPath(int frames) const {
    std::vector<PointLight> lights;
    const double half = 0.5 * (gridSide - 1) * spacingMm * 0.9;
    const double y = 548.8 - belowCeilingMm;
    for (int f = 0; f < frames; ++f) {
        const double t = 2.0 * M_PI * f / frames;
        lights.push_back(
            {v(278.0 + half * std::sin(t), y + 4.0 * std::sin(3 * t), 279.6 + half * std::sin(2 * t + 0.5)),
             intensity});
    }
    return lights;
}

std::vector<PointLight> LightRig::outsideLights() const {
    std::vector<PointLight> lights;
    const double y = 548.8 - belowCeilingMm;
    // Lower: four places clear of both blocks in x and z (the short block spans x 82-240,
    // z 65-225; the tall one x 265-430, z 247-406).
    const double places[4][2] = {{150, 420}, {450, 120}, {278, 150}, {278, 480}};
    for (const double below : {120.0, 220.0, 320.0})
        for (const auto& xz : places) lights.push_back({v(xz[0], y - below, xz[1]), intensity});
    // Beyond the grid (x and z within 80-478 mm), 30 mm from the walls.
    const double lo = 30, hiX = 556 - 30, hiZ = 559.2 - 30, midX = 278, midZ = 279.6;
    const double rim[8][2] = {{lo, lo},   {hiX, lo},   {lo, hiZ},  {hiX, hiZ},
                              {lo, midZ}, {hiX, midZ}, {midX, lo}, {midX, hiZ}};
    for (const auto& xz : rim) lights.push_back({v(xz[0], y, xz[1]), intensity});
    // Cool white on the training plane: the same power, another colour.
    const Rgb cool{1.0e5, 1.3e5, 1.8e5};
    const double onPlane[4][2] = {{150, 150}, {400, 400}, {278, 279.6}, {200, 420}};
    for (const auto& xz : onPlane) lights.push_back({v(xz[0], y, xz[1]), cool});
    return lights;
}

std::vector<Camera> demoCameras(double t) {
    std::vector<Camera> cams;
    // The measured view, dollying in a little so the standard camera moves too.
    cams.push_back({"standard", v(278, 273, -800 + 200 * t), v(278, 273, 0), v(0, 1, 0), 39.3077});
    // An orbit around the opening, looking at the blocks.
    const double a = -0.35 + 0.7 * t;
    cams.push_back({"orbit", v(278 + 700 * std::sin(a), 380, 279.6 - 700 * std::cos(a)), v(278, 180, 300),
                    v(0, 1, 0), 50.0});
    // Inside the box, near the front left corner, panning across the back wall and blocks.
    const double b = 0.25 + 0.5 * t;
    cams.push_back({"inside", v(480, 420, 60),
                    v(480 - 400 * std::sin(b * M_PI), 150, 60 + 400 * std::cos(b * M_PI * 0.5) + 200),
                    v(0, 1, 0), 70.0});
    return cams;
}

}  // namespace pmsc::cornell
