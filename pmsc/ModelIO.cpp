#include "pmsc/ModelIO.h"

#include "pmsc/AtomicFile.h"
#include "pmsc/BulkAllocator.h"
#include "pmsc/ByteIO.h"
#include "pmsc/Errors.h"
#include "pmsc/ModelSections.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <set>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace pmsc {

namespace {

constexpr char kModelMagic[8] = {'P', 'M', 'S', 'C', 'M', 'O', 'D', 'L'};

[[noreturn]] void bad(const std::string& name, const std::string& what) {
    throw InputError(name + ": " + what);
}

template <class T>
void put(std::string& out, T value) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    out.append(bytes, sizeof(T));
}

void putDoubles(std::string& out, const double* values, std::size_t count) {
    out.append(reinterpret_cast<const char*>(values), count * sizeof(double));
}

template <class T>
T get(std::string_view bytes, std::size_t offset) {
    T value;
    std::memcpy(&value, bytes.data() + offset, sizeof(T));
    return value;
}

/// a*b and a+b for sizes read from a file, refusing to wrap.
bool mulOk(std::uint64_t a, std::uint64_t b, std::uint64_t& out) {
    return !__builtin_mul_overflow(a, b, &out);
}
bool addOk(std::uint64_t a, std::uint64_t b, std::uint64_t& out) {
    return !__builtin_add_overflow(a, b, &out);
}

/// The sections of a version-2 file: `bytes` runs from the section count to the checksum.
void decodeSections(std::string_view bytes, const std::string& name, Model& model) {
    ByteReader table(bytes, name);
    // Every section takes at least its 16-byte tag and length.
    const std::uint64_t count = table.count("section count", 16);
    std::set<std::string> seen;
    const std::string readerName = name + ": ";  // + "section 'TAG'": what a section's errors name
    for (std::uint64_t i = 0; i < count; ++i) {
        const std::string where = "section #" + std::to_string(i);
        char tag[8];
        std::memcpy(tag, table.take(8, where + " tag").data(), 8);
        const std::string text = tagText(tag);
        const std::uint64_t payload = table.u64("section '" + text + "' length");
        if (payload > table.remaining())
            table.fail("section '" + text + "' has bad length " + std::to_string(payload) + ": only " +
                       std::to_string(table.remaining()) + " bytes remain before the checksum");
        const ModelSectionCodec* codec = nullptr;
        for (const ModelSectionCodec& c : modelSectionCodecs())
            if (std::memcmp(c.tag.data(), tag, 8) == 0) codec = &c;
        if (!codec)
            table.fail("unknown section '" + text + "' (written by a newer pmsc? this build knows " + [] {
                std::string known;
                for (const ModelSectionCodec& c : modelSectionCodecs())
                    known += (known.empty() ? "'" : ", '") + tagText(c.tag.data()) + "'";
                return known;
            }() + ")");
        const std::string section = "section '" + text + "'";
        if (!seen.insert(std::string(tag, 8)).second) table.fail(section + " appears twice");
        ByteReader reader(table.take(payload, section + " payload"), readerName + section);
        codec->decode(reader, model);
        reader.expectEnd();
    }
    table.expectEnd();
}

}  // namespace

std::uint64_t fnv1a64(const void* data, std::size_t bytes) {
    const unsigned char* p = static_cast<const unsigned char*>(data);
    std::uint64_t hash = 0xcbf29ce484222325ull;
    for (std::size_t i = 0; i < bytes; ++i) {
        hash ^= p[i];
        hash *= 0x100000001b3ull;
    }
    return hash;
}

std::uint32_t modelFormatVersion(const Model& model) {
    if (model.sharedChannels) return kModelFormatVersionFlags;
    for (const ModelSectionCodec& codec : modelSectionCodecs())
        if (codec.present(model)) return kModelFormatVersionSections;
    return kModelFormatVersionCore;
}

std::string encodeModel(const Model& model) {
    model.validate();
    const std::uint64_t n = static_cast<std::uint64_t>(model.points);
    const std::uint64_t c = static_cast<std::uint64_t>(model.channels);
    const std::uint64_t m = static_cast<std::uint64_t>(model.basisSize());
    const std::uint64_t k = static_cast<std::uint64_t>(model.keyCount());
    std::vector<const ModelSectionCodec*> sections;
    for (const ModelSectionCodec& codec : modelSectionCodecs())
        if (codec.present(model)) sections.push_back(&codec);
    std::string out;
    out.reserve(kModelHeaderBytes + 8 * (n * c * (m + 1) + m + k + m * k * c + 1));
    out.append(kModelMagic, sizeof kModelMagic);
    const std::uint32_t version = modelFormatVersion(model);
    put<std::uint32_t>(out, version);
    put<std::uint32_t>(out, 0);
    put<std::uint64_t>(out, n);
    put<std::uint64_t>(out, c);
    put<std::uint64_t>(out, m);
    put<std::uint64_t>(out, k);
    put<std::uint64_t>(out, static_cast<std::uint64_t>(model.trainFrames));
    put<std::uint32_t>(out, static_cast<std::uint32_t>(model.selector));
    put<std::uint32_t>(out, model.sharedChannels ? kModelFlagSharedChannels : 0u);
    put<double>(out, model.epsMin);
    put<double>(out, model.epsMax);
    put<double>(out, model.tolerance);
    put<double>(out, model.trainMaxPointResidual);
    put<double>(out, model.totalEnergy);
    putDoubles(out, model.mean.data(), n * c);
    const std::uint64_t bc = static_cast<std::uint64_t>(model.basisChannels());
    putDoubles(out, model.basis.data(), n * bc * m);
    putDoubles(out, model.singularValues.data(), m);
    for (const Index key : model.keyPoints) put<std::uint64_t>(out, static_cast<std::uint64_t>(key));
    putDoubles(out, model.projector.data(), m * k * bc);
    if (version >= kModelFormatVersionSections) {
        put<std::uint64_t>(out, sections.size());
        for (const ModelSectionCodec* codec : sections) {
            out.append(codec->tag.data(), codec->tag.size());
            const std::size_t lengthAt = out.size();
            put<std::uint64_t>(out, 0);  // the payload's length, known once it is written
            ByteWriter writer(out);
            codec->encode(model, writer);
            const std::uint64_t length = out.size() - lengthAt - 8;
            std::memcpy(out.data() + lengthAt, &length, 8);
        }
    }
    put<std::uint64_t>(out, fnv1a64(out.data(), out.size()));
    return out;
}

namespace {

/// The magic, the length a header needs, and a version this build reads; returns the version.
std::uint32_t checkVersion(std::string_view bytes, const std::string& name) {
    const std::uint64_t length = bytes.size();
    // The file's first bytes against as many of the magic's: a short file whose bytes match is
    // reported as truncated below, and an empty one (whose buffer may be null; string_view compares
    // it without reading) matches the empty prefix.
    const std::size_t prefix = std::min<std::size_t>(length, sizeof kModelMagic);
    if (bytes.substr(0, prefix) != std::string_view(kModelMagic, prefix))
        bad(name, "not a pmsc model file (bad magic; expected \"PMSCMODL\")");
    if (length < kModelHeaderBytes + 8)
        bad(name, "truncated model file (" + std::to_string(length) + " bytes; the header alone needs " +
                      std::to_string(kModelHeaderBytes + 8) + ")");
    const auto version = get<std::uint32_t>(bytes, 8);
    if (version < kModelFormatVersionCore || version > kModelFormatVersion)
        bad(name, "unsupported model format version " + std::to_string(version) +
                      " (this build reads versions " + std::to_string(kModelFormatVersionCore) + " to " +
                      std::to_string(kModelFormatVersion) + ")");
    return version;
}

/// The header's sizes and the array lengths they imply.
struct CoreLayout {
    std::uint64_t n = 0, c = 0, m = 0, k = 0, trainFrames = 0;
    std::uint32_t selector = 0;
    bool shared = false;
    std::uint64_t nc = 0, nb = 0, ncm = 0, kc = 0, mkc = 0;
    std::uint64_t coreEnd = 0;  ///< where the sections (version 2) or the checksum begin
    std::string sizes;          ///< "N=.., C=.., M=.., K=.." for messages
};

/// Reads the header's sizes and flags and checks that the file is exactly as long as they say.
CoreLayout readLayout(std::string_view bytes, const std::string& name, std::uint32_t version) {
    const std::uint64_t length = bytes.size();
    const bool hasSections = version >= 2;
    CoreLayout h;
    h.n = get<std::uint64_t>(bytes, 16);
    h.c = get<std::uint64_t>(bytes, 24);
    h.m = get<std::uint64_t>(bytes, 32);
    h.k = get<std::uint64_t>(bytes, 40);
    h.trainFrames = get<std::uint64_t>(bytes, 48);
    h.selector = get<std::uint32_t>(bytes, 56);
    const auto flags = get<std::uint32_t>(bytes, 60);
    h.sizes = "N=" + std::to_string(h.n) + ", C=" + std::to_string(h.c) + ", M=" + std::to_string(h.m) +
              ", K=" + std::to_string(h.k);
    const std::string& sizes = h.sizes;
    if (h.n == 0 || h.c == 0 || h.m == 0 || h.k == 0)
        bad(name, "inconsistent sizes in the header (" + sizes + "): all must be positive");

    if (version < kModelFormatVersionFlags && flags != 0)
        bad(name, "the header's reserved word (offset 60) is " + std::to_string(flags) +
                      ", not 0, in a version-" + std::to_string(version) + " file");
    if ((flags & ~kModelFlagSharedChannels) != 0)
        bad(name,
            "unknown model flags " + std::to_string(flags) + " (this build knows only 1: shared channels)");
    h.shared = (flags & kModelFlagSharedChannels) != 0;
    // Expected length = header + 8*(N*C + N*B*M + M + K + M*K*B) + checksum, B = C (or 1 when
    // the channels share the basis), all computed without wrapping; only a file that is exactly
    // that long is parsed (version 2: at least that long plus the section count), so every
    // allocation below is bounded by the real file length.
    const std::uint64_t b = h.shared ? 1 : h.c;
    std::uint64_t values = 0, expected = 0;
    const bool ok = mulOk(h.n, h.c, h.nc) && mulOk(h.n, b, h.nb) && mulOk(h.nb, h.m, h.ncm) &&
                    mulOk(h.k, b, h.kc) && mulOk(h.m, h.kc, h.mkc) && addOk(h.nc, h.ncm, values) &&
                    addOk(values, h.m, values) && addOk(values, h.k, values) &&
                    addOk(values, h.mkc, values) && mulOk(values, 8, expected) &&
                    addOk(expected, kModelHeaderBytes + 8, expected);
    if (!ok)
        bad(name, "inconsistent sizes in the header (" + sizes + "): the arrays would not fit in any file");
    h.coreEnd = expected - 8;
    if (hasSections && !addOk(expected, 8, expected))
        bad(name, "inconsistent sizes in the header (" + sizes + "): the arrays would not fit in any file");
    if (hasSections ? length < expected : expected != length) {
        if (length < expected)
            bad(name, "truncated model file or corrupted header: the header (" + sizes + ") needs " +
                          std::to_string(expected) + " bytes, the file has " + std::to_string(length));
        bad(name, "inconsistent sizes: the header (" + sizes + ") needs " + std::to_string(expected) +
                      " bytes, the file has " + std::to_string(length) + " (" +
                      std::to_string(length - expected) + " extra)");
    }
    return h;
}

/// The stored checksum against the one of the bytes before it.
void checkChecksum(std::string_view bytes, const std::string& name) {
    const std::uint64_t length = bytes.size();
    const auto stored = get<std::uint64_t>(bytes, length - 8);
    const auto computed = fnv1a64(bytes.data(), length - 8);
    if (stored != computed) {
        char detail[96];
        std::snprintf(detail, sizeof detail, " (stored %016llx, computed %016llx)",
                      static_cast<unsigned long long>(stored), static_cast<unsigned long long>(computed));
        bad(name, std::string("checksum mismatch: the model file is corrupted") + detail);
    }
}

/// The header's values that its sizes alone do not bound.
void checkHeaderValues(const CoreLayout& h, const std::string& name) {
    if (h.selector > static_cast<std::uint32_t>(Selector::QDeim))
        bad(name, "unknown key-point selector " + std::to_string(h.selector));
    if (h.m > h.nb) bad(name, "inconsistent sizes (" + h.sizes + "): more basis vectors than basis rows");
    if (h.k > h.n) bad(name, "inconsistent sizes (" + h.sizes + "): more key points than points");
    if (h.trainFrames > static_cast<std::uint64_t>(INT64_MAX))
        bad(name, "inconsistent header: " + std::to_string(h.trainFrames) + " training frames");
}

/// The core model: the header's scalars and the arrays after it.
Model readCore(std::string_view bytes, const std::string& name, const CoreLayout& h) {
    Model model;
    model.points = static_cast<Index>(h.n);
    model.channels = static_cast<Index>(h.c);
    model.trainFrames = static_cast<Index>(h.trainFrames);
    model.selector = static_cast<Selector>(h.selector);
    model.sharedChannels = h.shared;
    model.epsMin = get<double>(bytes, 64);
    model.epsMax = get<double>(bytes, 72);
    model.tolerance = get<double>(bytes, 80);
    model.trainMaxPointResidual = get<double>(bytes, 88);
    model.totalEnergy = get<double>(bytes, 96);
    std::size_t at = kModelHeaderBytes;
    const auto readDoubles = [&](double* out, std::uint64_t count) {
        std::memcpy(out, bytes.data() + at, count * sizeof(double));
        at += count * sizeof(double);
    };
    model.mean.resize(static_cast<Index>(h.nc));
    readDoubles(model.mean.data(), h.nc);
    model.basis.resize(static_cast<Index>(h.nb), static_cast<Index>(h.m));
    readDoubles(model.basis.data(), h.ncm);
    model.singularValues.resize(static_cast<Index>(h.m));
    readDoubles(model.singularValues.data(), h.m);
    model.keyPoints.resize(h.k);
    for (auto& key : model.keyPoints) {
        const auto raw = get<std::uint64_t>(bytes, at);
        at += 8;
        if (raw >= h.n)
            bad(name,
                "key point index " + std::to_string(raw) + " is outside [0, " + std::to_string(h.n) + ")");
        key = static_cast<Index>(raw);
    }
    model.projector.resize(static_cast<Index>(h.m), static_cast<Index>(h.kc));
    readDoubles(model.projector.data(), h.mkc);
    return model;
}

/// Model::validate, its complaint reported as the file's.
void validateDecoded(const Model& model, const std::string& name) {
    try {
        model.validate();
    } catch (const std::invalid_argument& e) {
        bad(name, std::string("inconsistent model: ") + e.what());
    }
}

/// The header's values, the core arrays and the sections, each checked (not the checksum).
Model decodeContents(std::string_view bytes, const std::string& name, const CoreLayout& layout,
                     std::uint32_t version) {
    checkHeaderValues(layout, name);
    Model model = readCore(bytes, name, layout);
    validateDecoded(model, name);
    if (version >= 2) {
        decodeSections(bytes.substr(layout.coreEnd, bytes.size() - 8 - layout.coreEnd), name, model);
        // Again with the sections: what they may not be combined with (shared channels have none).
        validateDecoded(model, name);
    }
    return model;
}

}  // namespace

Model decodeModel(std::string_view bytes, const std::string& name, ChecksumThread where) {
    const std::uint32_t version = checkVersion(bytes, name);
    const CoreLayout layout = readLayout(bytes, name, version);
    if (where == ChecksumThread::First || bytes.size() < kChecksumThreadBytes) {
        checkChecksum(bytes, name);
        return decodeContents(bytes, name, layout, version);
    }
    std::exception_ptr checksumError;
    std::thread checksum;
    try {
        checksum = std::thread([&] {
            try {
                checkChecksum(bytes, name);
            } catch (...) {
                checksumError = std::current_exception();
            }
        });
    } catch (const std::system_error&) {  // no thread to be had: one after the other
        checkChecksum(bytes, name);
        return decodeContents(bytes, name, layout, version);
    }
    // The checksum's verdict comes first, as when it is checked before the contents: a corrupted file
    // is reported as corrupted, whatever its contents would have been refused for. The decode reads
    // only within the lengths readLayout checked against the file, so corrupted bytes cannot lead it
    // outside them.
    Model model;
    std::exception_ptr decodeError;
    try {
        model = decodeContents(bytes, name, layout, version);
    } catch (...) {
        decodeError = std::current_exception();
    }
    checksum.join();
    if (checksumError) std::rethrow_exception(checksumError);
    if (decodeError) std::rethrow_exception(decodeError);
    return model;
}

void writeModel(const std::string& path, const Model& model) {
    writeFileAtomically(path, encodeModel(model));
}

Model readModel(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        const int error = errno;
        bad(path, error == ENOENT ? std::string("no such file")
                                  : std::string("cannot open: ") + std::strerror(error));
    }
    struct Closer {
        int fd;
        ~Closer() { ::close(fd); }
    } closer{fd};
    struct stat st {};
    if (::fstat(fd, &st) != 0) bad(path, std::string("cannot stat: ") + std::strerror(errno));
    if (S_ISDIR(st.st_mode)) bad(path, "is a folder, not a model file");
    // The buffer is as large as the file really is; nothing is allocated from a size field.
    const auto size = static_cast<std::size_t>(st.st_size);
    // BulkAllocator: no zero fill (read() writes it), and huge pages when large, as a model of
    // hundreds of megabytes is read at every `pmsc run` task's start.
    std::vector<char, BulkAllocator<char>> buffer(size);
    std::size_t done = 0;
    while (done < size) {
        const ssize_t got = ::read(fd, buffer.data() + done, size - done);
        if (got < 0) {
            if (errno == EINTR) continue;
            bad(path, std::string("read failed: ") + std::strerror(errno));
        }
        if (got == 0) break;
        done += static_cast<std::size_t>(got);
    }
    return decodeModel(std::string_view(buffer.data(), done), path);
}

}  // namespace pmsc
