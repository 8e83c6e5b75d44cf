#include "evaluators/face/FaceAnimation.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <utility>

namespace pmsc::face {
namespace {

// Uniform doubles from the raw engine: std::uniform_real_distribution is implementation-defined,
// and the animation must be the same on every machine that builds the project.
class Random {
public:
    explicit Random(std::uint64_t seed) : engine_(seed) {}
    double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
    double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
    Index integer(Index lo, Index hi) {
        return lo + static_cast<Index>(uniform() * static_cast<double>(hi - lo + 1));
    }
    bool chance(double p) { return uniform() < p; }

private:
    std::mt19937_64 engine_;
};

using Target = std::vector<std::pair<int, double>>;

// Keyed curve of one control: smoothstep between keys (C1, no overshoot), held outside them.
class Track {
public:
    void key(double t, double v) { keys_.emplace_back(t, v); }
    bool empty() const { return keys_.empty(); }
    double at(double t) {
        if (keys_.empty()) return 0;
        if (!sorted_) {
            std::stable_sort(keys_.begin(), keys_.end(), [](auto& a, auto& b) { return a.first < b.first; });
            sorted_ = true;
        }
        if (t <= keys_.front().first) return keys_.front().second;
        if (t >= keys_.back().first) return keys_.back().second;
        const auto hi =
            std::upper_bound(keys_.begin(), keys_.end(), t, [](double x, auto& k) { return x < k.first; });
        const auto lo = hi - 1;
        const double span = hi->first - lo->first;
        const double s = span > 0 ? (t - lo->first) / span : 1.0;
        const double w = s * s * (3 - 2 * s);
        return lo->second + w * (hi->second - lo->second);
    }

private:
    std::vector<std::pair<double, double>> keys_;
    bool sorted_ = false;
};

// Mouth shapes of speech (visemes). Values were set by looking at the ICT shapes: enough jaw
// to read, lips that round, spread, press and roll.
const std::vector<Target>& visemes() {
    static const std::vector<Target> table = {
        /* AA */ {{JawOpen, 0.55},
                  {MouthLowerDownL, 0.25},
                  {MouthLowerDownR, 0.25},
                  {MouthStretchL, 0.1},
                  {MouthStretchR, 0.1}},
        /* EH */
        {{JawOpen, 0.35},
         {MouthStretchL, 0.3},
         {MouthStretchR, 0.3},
         {MouthSmileL, 0.15},
         {MouthSmileR, 0.15},
         {MouthUpperUpL, 0.1},
         {MouthUpperUpR, 0.1}},
        /* IY */
        {{JawOpen, 0.15},
         {MouthStretchL, 0.45},
         {MouthStretchR, 0.45},
         {MouthSmileL, 0.3},
         {MouthSmileR, 0.3}},
        /* OW */ {{JawOpen, 0.35}, {MouthFunnel, 0.5}, {MouthPucker, 0.3}},
        /* UW */ {{JawOpen, 0.15}, {MouthPucker, 0.75}, {MouthFunnel, 0.3}},
        /* MBP */
        {{JawOpen, 0.04},
         {MouthPressL, 0.45},
         {MouthPressR, 0.45},
         {MouthRollLower, 0.15},
         {MouthRollUpper, 0.1}},
        /* FV */ {{JawOpen, 0.12}, {MouthRollLower, 0.5}, {MouthUpperUpL, 0.2}, {MouthUpperUpR, 0.2}},
        /* TH/L/D */ {{JawOpen, 0.25}, {MouthStretchL, 0.2}, {MouthStretchR, 0.2}},
        /* S/Z */
        {{JawOpen, 0.08},
         {MouthStretchL, 0.35},
         {MouthStretchR, 0.35},
         {MouthSmileL, 0.2},
         {MouthSmileR, 0.2}},
        /* CH/SH */ {{JawOpen, 0.2}, {MouthFunnel, 0.45}, {MouthShrugUpper, 0.2}, {MouthPucker, 0.2}},
        /* R/W */ {{JawOpen, 0.15}, {MouthPucker, 0.5}, {MouthFunnel, 0.25}},
        /* K/G */ {{JawOpen, 0.3}, {MouthStretchL, 0.15}, {MouthStretchR, 0.15}, {MouthClose, 0.05}},
    };
    return table;
}

const std::vector<int>& speechControls() {
    static const std::vector<int> controls = {
        JawOpen,     MouthLowerDownL, MouthLowerDownR, MouthStretchL,   MouthStretchR, MouthSmileL,
        MouthSmileR, MouthUpperUpL,   MouthUpperUpR,   MouthFunnel,     MouthPucker,   MouthPressL,
        MouthPressR, MouthRollLower,  MouthRollUpper,  MouthShrugUpper, MouthClose};
    return controls;
}

const std::vector<Target>& emotions() {
    static const std::vector<Target> table = {
        /* neutral */ {},
        /* happy */
        {{MouthSmileL, 0.65},
         {MouthSmileR, 0.65},
         {CheekSquintL, 0.5},
         {CheekSquintR, 0.5},
         {EyeSquintL, 0.25},
         {EyeSquintR, 0.25},
         {CheekRaiserL, 0.3},
         {CheekRaiserR, 0.3},
         {MouthDimpleL, 0.2},
         {MouthDimpleR, 0.2}},
        /* sad */
        {{MouthFrownL, 0.55},
         {MouthFrownR, 0.55},
         {BrowInnerUpL, 0.6},
         {BrowInnerUpR, 0.6},
         {MouthShrugLower, 0.3}},
        /* surprise */
        {{BrowInnerUpL, 0.7},
         {BrowInnerUpR, 0.7},
         {BrowOuterUpL, 0.7},
         {BrowOuterUpR, 0.7},
         {EyeWideL, 0.6},
         {EyeWideR, 0.6},
         {JawOpen, 0.2}},
        /* anger */
        {{BrowDownL, 0.7},
         {BrowDownR, 0.7},
         {NoseSneerL, 0.35},
         {NoseSneerR, 0.35},
         {EyeSquintL, 0.35},
         {EyeSquintR, 0.35},
         {MouthPressL, 0.3},
         {MouthPressR, 0.3}},
        /* disgust */
        {{NoseSneerL, 0.6},
         {NoseSneerR, 0.6},
         {MouthUpperUpL, 0.45},
         {MouthUpperUpR, 0.45},
         {BrowDownL, 0.3},
         {BrowDownR, 0.3},
         {CheekSquintL, 0.3},
         {CheekSquintR, 0.3},
         {MouthFrownL, 0.2},
         {MouthFrownR, 0.2}},
        /* contempt */ {{MouthSmileL, 0.45}, {MouthDimpleL, 0.45}, {EyeSquintL, 0.15}, {BrowDownR, 0.2}},
        /* fear */
        {{BrowInnerUpL, 0.6},
         {BrowInnerUpR, 0.6},
         {BrowOuterUpL, 0.3},
         {BrowOuterUpR, 0.3},
         {EyeWideL, 0.5},
         {EyeWideR, 0.5},
         {MouthStretchL, 0.45},
         {MouthStretchR, 0.45}},
    };
    return table;
}

// The character's left and right swapped (x -> -x): used to vary asymmetric expressions.
int mirror(int c) {
    static const std::vector<std::pair<int, int>> pairs = {{BrowDownL, BrowDownR},
                                                           {BrowInnerUpL, BrowInnerUpR},
                                                           {BrowOuterUpL, BrowOuterUpR},
                                                           {CheekPuffL, CheekPuffR},
                                                           {CheekRaiserL, CheekRaiserR},
                                                           {CheekSquintL, CheekSquintR},
                                                           {EyeSquintL, EyeSquintR},
                                                           {EyeWideL, EyeWideR},
                                                           {MouthDimpleL, MouthDimpleR},
                                                           {MouthFrownL, MouthFrownR},
                                                           {MouthLowerDownL, MouthLowerDownR},
                                                           {MouthPressL, MouthPressR},
                                                           {MouthSmileL, MouthSmileR},
                                                           {MouthStretchL, MouthStretchR},
                                                           {MouthUpperUpL, MouthUpperUpR},
                                                           {NoseSneerL, NoseSneerR},
                                                           {PupilDilateL, PupilDilateR},
                                                           {EyeBlinkL, EyeBlinkR},
                                                           {MouthLeft, MouthRight},
                                                           {JawLeft, JawRight}};
    for (auto [a, b] : pairs) {
        if (c == a) return b;
        if (c == b) return a;
    }
    return c;
}

bool isLeft(int c) { return mirror(c) != c && controlName(c).back() == 'L'; }

// One keyed curve per control.
using Tracks = std::array<Track, kControlCount>;

/// Speech: utterances of visemes every 3.5-6 frames, separated by pauses; every speech
/// control is keyed at every viseme so neighbouring visemes blend (co-articulation). The brows'
/// emphasis on stressed syllables goes to `accent`.
void keySpeech(Random& rng, double end, Tracks& speech, Tracks& accent) {
    double t = rng.uniform(0, 12);
    double lastAccent = -1e9;
    for (int c : speechControls()) speech[c].key(0, 0);
    while (t < end) {
        const double utteranceEnd = t + rng.uniform(24, 72);
        while (t < std::min(utteranceEnd, end)) {
            const Target& v =
                visemes()[static_cast<size_t>(rng.integer(0, static_cast<Index>(visemes().size()) - 1))];
            const double amplitude = rng.uniform(0.7, 1.15);
            const double asymmetry = rng.uniform(-0.1, 0.1);
            for (int c : speechControls()) {
                double value = 0;
                for (auto [vc, vv] : v) {
                    if (vc == c) value = vv * amplitude * (1 + (isLeft(c) ? asymmetry : -asymmetry));
                }
                speech[c].key(t, value);
            }
            if (rng.chance(0.12) && t > lastAccent + 12) {  // emphasis: the brows lift on a stressed syllable
                lastAccent = t;
                const double lift = rng.uniform(0.2, 0.45);
                for (int c : {BrowInnerUpL, BrowInnerUpR, BrowOuterUpL, BrowOuterUpR}) {
                    accent[c].key(t - 4, 0);
                    accent[c].key(t, lift);
                    accent[c].key(t + 6, 0);
                }
            }
            t += rng.uniform(3.5, 6.0);
        }
        for (int c : speechControls()) speech[c].key(t, 0);
        t += rng.uniform(8, 24);
    }
}

/// Emotions: held 0.7-2 s, 8-14 frame transitions, random intensity, sometimes mirrored.
void keyEmotions(Random& rng, double end, Tracks& emotion) {
    double t = 0;
    Target previous;
    while (t <= end) {
        const Target& e =
            emotions()[static_cast<size_t>(rng.integer(0, static_cast<Index>(emotions().size()) - 1))];
        const double intensity = rng.uniform(0.4, 1.0);
        const bool mirrored = rng.chance(0.5);
        Target now;
        for (auto [c, v] : e) now.emplace_back(mirrored ? mirror(c) : c, v * intensity);
        const double ramp = t == 0 ? 0 : rng.uniform(8, 14);
        for (int c = 0; c < kControlCount; ++c) {
            double before = 0, after = 0;
            for (auto [pc, pv] : previous) before += pc == c ? pv : 0;
            for (auto [nc, nv] : now) after += nc == c ? nv : 0;
            if (before == 0 && after == 0) continue;
            if (ramp > 0) emotion[c].key(t, before);  // the first emotion is there from frame 0
            emotion[c].key(t + ramp, after);
        }
        for (auto [c, v] : now) emotion[c].key(t + ramp, v);
        previous = now;
        t += ramp + rng.uniform(16, 48);
    }
    for (int c = 0; c < kControlCount; ++c) {
        if (!emotion[c].empty()) {
            double held = 0;
            for (auto [pc, pv] : previous) held += pc == c ? pv : 0;
            emotion[c].key(end + 1, held);
        }
    }
}

/// The eyes: blinks every 2-5 s (3 frames closing, 4 opening), sometimes partial or a wink;
/// gaze fixations joined by saccades; pupils that drift.
void keyEyes(Random& rng, double end, Tracks& eyes) {
    eyes[EyeBlinkL].key(0, 0);
    eyes[EyeBlinkR].key(0, 0);
    for (double b = rng.uniform(4, 60); b < end; b += rng.uniform(48, 120)) {
        const double depth = rng.chance(0.15) ? rng.uniform(0.5, 0.8) : 1.0;
        const bool wink = rng.chance(0.05);
        const int winkEye = rng.chance(0.5) ? EyeBlinkL : EyeBlinkR;
        for (int c : {EyeBlinkL, EyeBlinkR}) {
            if (wink && c != winkEye) continue;
            eyes[c].key(b - 3, 0);
            eyes[c].key(b, depth);
            eyes[c].key(b + 4, 0);
        }
    }
    // Gaze: fixations of 0.5-2 s joined by 3-frame saccades.
    double yaw = rng.uniform(-10, 10), pitch = rng.uniform(-5, 5);
    eyes[GazeYaw].key(0, yaw);
    eyes[GazePitch].key(0, pitch);
    for (double g = rng.uniform(12, 48); g < end; g += rng.uniform(12, 48)) {
        eyes[GazeYaw].key(g, yaw);
        eyes[GazePitch].key(g, pitch);
        yaw = rng.uniform(-25, 25);
        pitch = rng.uniform(-15, 12);
        eyes[GazeYaw].key(g + 3, yaw);
        eyes[GazePitch].key(g + 3, pitch);
    }
    // Pupils drift slowly.
    for (int c : {PupilDilateL, PupilDilateR}) eyes[c].key(0, 0);
    for (double p = 0; p < end + 48; p += rng.uniform(24, 48)) {
        const double v = rng.uniform(0, 0.4);
        eyes[PupilDilateL].key(p, v);
        eyes[PupilDilateR].key(p, v);
    }
}

/// Novel: one or two controls held in [kNovelMin, 1] through the whole shot.
void keyNovel(Random& rng, double end, const std::vector<int>& novelPool, std::vector<int>& novelUsed,
              Tracks& extra) {
    const Index count = rng.integer(1, 2);
    for (Index i = 0; i < count; ++i) {
        int c = novelPool[static_cast<size_t>(rng.integer(0, static_cast<Index>(novelPool.size()) - 1))];
        if (std::find(novelUsed.begin(), novelUsed.end(), c) != novelUsed.end()) continue;
        if (std::find(novelUsed.begin(), novelUsed.end(), mirror(c)) != novelUsed.end() &&
            (c == JawLeft || c == JawRight || c == MouthLeft || c == MouthRight)) {
            continue;  // left and right at once cancel out
        }
        novelUsed.push_back(c);
        for (double k = 0; k < end + 24; k += rng.uniform(12, 24)) {
            extra[c].key(k, rng.uniform(FaceAnimation::kNovelMin, 1.0));
        }
    }
}

/// Mixed: the same controls as novel ones for 24-72 frames (1-3 s) only, with 6-frame ramps.
void keyMixed(Random& rng, double end, const std::vector<int>& novelPool, std::vector<int>& novelUsed,
              Tracks& extra) {
    const Index count = rng.integer(1, 2);
    const double hold = rng.uniform(24, 72);
    const double start = rng.uniform(6, std::max(7.0, end - hold - 12));
    for (Index i = 0; i < count; ++i) {
        const int c =
            novelPool[static_cast<size_t>(rng.integer(0, static_cast<Index>(novelPool.size()) - 1))];
        if (std::find(novelUsed.begin(), novelUsed.end(), c) != novelUsed.end() ||
            std::find(novelUsed.begin(), novelUsed.end(), mirror(c)) != novelUsed.end()) {
            continue;
        }
        novelUsed.push_back(c);
        extra[c].key(0, 0);
        extra[c].key(start, 0);
        for (double k = start + 6; k < start + 6 + hold; k += rng.uniform(12, 24)) {
            extra[c].key(k, rng.uniform(FaceAnimation::kNovelMin, 1.0));
        }
        extra[c].key(start + 6 + hold, rng.uniform(FaceAnimation::kNovelMin, 1.0));
        extra[c].key(start + 12 + hold, 0);
    }
}

/// The frames: each control the clamped sum of its tracks; the gaze as keyed.
void poseFrames(Index frames, Tracks& speech, Tracks& emotion, Tracks& accent, Tracks& eyes, Tracks& extra,
                double gazeDistance, double lipStick, std::vector<ControlVector>& out) {
    for (Index f = 0; f < frames; ++f) {
        const double x = static_cast<double>(f);
        ControlVector pose = restPose();
        for (int c = 0; c < kControlCount; ++c) {
            if (c == GazeYaw || c == GazePitch) {
                pose[c] = eyes[c].at(x);
                continue;
            }
            const double v =
                speech[c].at(x) + emotion[c].at(x) + accent[c].at(x) + eyes[c].at(x) + extra[c].at(x);
            pose[c] = std::clamp(v, 0.0, 1.0);
        }
        pose[GazeDistance] = gazeDistance;
        pose[LipStick] = lipStick;
        out.push_back(pose);
    }
}

void generateSequence(Random& rng, Index frames, const std::vector<int>& novelPool, bool novel,
                      std::vector<ControlVector>& out, std::vector<int>& novelUsed, bool mixed = false) {
    Tracks speech, emotion, accent, eyes;
    const double end = static_cast<double>(frames - 1);
    keySpeech(rng, end, speech, accent);
    keyEmotions(rng, end, emotion);
    keyEyes(rng, end, eyes);
    const double gazeDistance = rng.uniform(35, 120);
    const double lipStick = rng.uniform(0.2, 0.8);
    Tracks extra;
    if (novel) keyNovel(rng, end, novelPool, novelUsed, extra);
    // Mixed: drawn after everything above, so the ordinary part is what the same stream would
    // give an ordinary shot.
    if (mixed) keyMixed(rng, end, novelPool, novelUsed, extra);
    poseFrames(frames, speech, emotion, accent, eyes, extra, gazeDistance, lipStick, out);
}

}  // namespace

FaceAnimation FaceAnimation::generate(const FaceAnimationOptions& options) {
    if (options.sequences < 1 || options.novelSequences < 0 || options.minFrames < 8 ||
        options.maxFrames < options.minFrames) {
        throw std::invalid_argument(
            "FaceAnimation: needs sequences >= 1, novelSequences >= 0 and 8 <= minFrames <= maxFrames");
    }
    if (options.novelSequences > 0 && options.novelControls.empty()) {
        throw std::invalid_argument("FaceAnimation: novel sequences need novel controls");
    }
    FaceAnimation animation;
    if (options.mixedSequences < 0 ||
        (options.mixedSequences > 0 &&
         (options.mixedMinFrames < 96 || options.mixedMaxFrames < options.mixedMinFrames))) {
        throw std::invalid_argument(
            "FaceAnimation: mixed sequences need 96 <= mixedMinFrames <= mixedMaxFrames");
    }
    if (options.mixedSequences > 0 && options.novelControls.empty()) {
        throw std::invalid_argument("FaceAnimation: mixed sequences need novel controls");
    }
    const Index total = options.sequences + options.novelSequences + options.mixedSequences;
    for (Index s = 0; s < total; ++s) {
        // Each sequence has its own stream, so adding sequences does not change the others.
        Random rng(static_cast<std::uint64_t>(options.seed) * 0x9E3779B97F4A7C15ull +
                   static_cast<std::uint64_t>(s) * 0xD1B54A32D192ED03ull + 1);
        const bool mixed = s >= options.sequences + options.novelSequences;
        const bool novel = !mixed && s >= options.sequences;
        FaceSequence seq;
        char name[32];
        if (mixed) {
            std::snprintf(name, sizeof name, "mixed%03ld",
                          static_cast<long>(s - options.sequences - options.novelSequences));
        } else {
            std::snprintf(name, sizeof name, novel ? "novel%03ld" : "seq%03ld",
                          static_cast<long>(novel ? s - options.sequences : s));
        }
        seq.name = name;
        seq.novel = novel;
        seq.mixed = mixed;
        seq.firstFrame = animation.frameCount();
        seq.frameCount = mixed ? rng.integer(options.mixedMinFrames, options.mixedMaxFrames)
                               : rng.integer(options.minFrames, options.maxFrames);
        generateSequence(rng, seq.frameCount, options.novelControls, novel, animation.frames_,
                         seq.novelControls, mixed);
        animation.sequences_.push_back(std::move(seq));
    }
    return animation;
}

std::vector<Index> FaceAnimation::framesOf(const std::vector<Index>& sequenceIndices) const {
    std::vector<Index> frames;
    for (Index s : sequenceIndices) {
        const FaceSequence& seq = sequences_.at(static_cast<size_t>(s));
        for (Index f = 0; f < seq.frameCount; ++f) frames.push_back(seq.firstFrame + f);
    }
    return frames;
}

void FaceAnimation::splitOrdinary(double fraction, unsigned seed, std::vector<Index>& training,
                                  std::vector<Index>& validation) const {
    std::vector<Index> ordinary;
    for (Index s = 0; s < static_cast<Index>(sequences_.size()); ++s) {
        if (!sequences_[s].novel && !sequences_[s].mixed) ordinary.push_back(s);
    }
    Random rng(seed);
    for (Index i = static_cast<Index>(ordinary.size()) - 1; i > 0; --i) {  // Fisher-Yates
        std::swap(ordinary[i], ordinary[rng.integer(0, i)]);
    }
    const Index count =
        std::clamp<Index>(static_cast<Index>(std::lround(fraction * static_cast<double>(ordinary.size()))), 1,
                          static_cast<Index>(ordinary.size()));
    training.assign(ordinary.begin(), ordinary.begin() + count);
    validation.assign(ordinary.begin() + count, ordinary.end());
    std::sort(training.begin(), training.end());
    std::sort(validation.begin(), validation.end());
}

}  // namespace pmsc::face
