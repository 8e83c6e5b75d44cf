// pmsc — Point Multiplication and Soft Caching (Meyer & Anderson, Pixar).
#pragma once

#include "pmsc/ByteIO.h"

#include <array>
#include <span>
#include <string>

namespace pmsc {

struct Model;

/// One optional part of a model file (format version 2, ModelIO.h): a feature's data, stored as a
/// tagged section {char tag[8], u64 byte length, payload}. Each feature encodes and decodes its
/// section in its own file (Regions.cpp for local fail-through, ...); ModelIO only finds the
/// codec by tag and hands it a bounds-checked reader over exactly the section's bytes.
struct ModelSectionCodec {
    std::array<char, 8> tag;  ///< ASCII, padded with '\0'
    /// Whether `model` has this section (a model without any is written as version 1).
    bool (*present)(const Model& model);
    void (*encode)(const Model& model, ByteWriter& out);
    /// Reads the payload into `model`, whose core (header and arrays) is already decoded and
    /// valid. Must read every byte (ModelIO checks) and reject bad values with `in.fail()`.
    void (*decode)(ByteReader& in, Model& model);
};

/// Every section this build knows, in the order they are written. Adding a feature's section is
/// one line in ModelSections.cpp.
std::span<const ModelSectionCodec> modelSectionCodecs();

/// A tag as text: the characters before the first '\0', non-printable bytes as \xNN.
std::string tagText(const char* tag);

}  // namespace pmsc
