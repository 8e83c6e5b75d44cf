// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "evaluators/face/FaceControls.h"

#include <string>
#include <vector>

namespace pmsc::face {

/// One shot of animation: a contiguous run of frames.
struct FaceSequence {
    std::string name;      ///< "seq017", "novel002"
    Index firstFrame = 0;  ///< in the whole animation
    Index frameCount = 0;
    bool novel = false;  ///< moves controls the ordinary sequences never move
    /// A "mixed" sequence: ordinary, with novel controls moved for a few seconds only
    /// (novel stays false: it is neither a training candidate nor part of the novel set).
    bool mixed = false;
    std::vector<int> novelControls;  ///< which ones
};

/// What to generate. The ordinary sequences are what an animator would key on a talking head:
/// speech (visemes with co-articulation), emotions that come and go (happy, sad, surprise,
/// anger, disgust, contempt), blinks, saccades between fixations, brow emphasis, pupil drift.
/// Novel sequences are ordinary ones that in addition hold one or two of `novelControls`
/// (never moved by an ordinary sequence) between kNovelMin and 1 for the whole shot: the
/// "animation control that was not exercised in the training set" of paper section 5.
struct FaceAnimationOptions {
    unsigned seed = 7;
    Index sequences = 36;  ///< ordinary sequences
    Index novelSequences = 8;
    /// Mixed sequences, after the novel ones: ordinary motion of mixedMinFrames..mixedMaxFrames
    /// frames in which one or two novel controls rise (6 frames), hold for 1-3 s and fall again,
    /// once, at a random time. 0 by default so `face:DIR` keeps its 44 sequences.
    Index mixedSequences = 0;
    Index mixedMinFrames = 120;
    Index mixedMaxFrames = 200;
    Index minFrames = 60;  ///< per sequence, at 24 frames per second
    Index maxFrames = 110;
    /// Controls only novel sequences move (and nothing else does).
    std::vector<int> novelControls = {CheekPuffL, CheekPuffR, JawForward, JawLeft,
                                      JawRight,   MouthLeft,  MouthRight};
};

/// A seeded, deterministic set of control curves: frame f -> ControlVector.
class FaceAnimation {
public:
    static constexpr double kFramesPerSecond = 24.0;
    static constexpr double kNovelMin = 0.5;

    /// Ordinary sequences first (indices 0 .. sequences-1), then the novel ones, then the mixed.
    static FaceAnimation generate(const FaceAnimationOptions& options);

    Index frameCount() const { return static_cast<Index>(frames_.size()); }
    const ControlVector& frame(Index f) const { return frames_.at(static_cast<size_t>(f)); }
    const std::vector<FaceSequence>& sequences() const { return sequences_; }

    /// Frames of the given sequences, in order (e.g. the training set).
    std::vector<Index> framesOf(const std::vector<Index>& sequenceIndices) const;

    /// Splits the ordinary sequences at random (seeded) into training (about `fraction` of
    /// them, at least one) and validation (the rest), as paper section 7 did (44 of 137).
    void splitOrdinary(double fraction, unsigned seed, std::vector<Index>& training,
                       std::vector<Index>& validation) const;

private:
    std::vector<ControlVector> frames_;
    std::vector<FaceSequence> sequences_;
};

}  // namespace pmsc::face
