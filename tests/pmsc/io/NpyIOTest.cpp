#include "pmsc/Errors.h"
#include "pmsc/NpyIO.h"

#include "tests/common/TempDir.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

using pmsc::FrameSet;
using pmsc::InputError;
using pmsc::NpyDtype;
using pmsc::test::TempDir;
using pmsc::test::writeBytes;

/// A .npy file built byte by byte, independent of the writer under test.
std::string npy(const std::string& dict, const std::string& data, int major = 1) {
    std::string header = dict;
    const std::size_t prefix = major == 1 ? 10 : 12;
    while ((prefix + header.size() + 1) % 64 != 0) header.push_back(' ');
    header.push_back('\n');
    std::string out("\x93NUMPY", 6);
    out.push_back(static_cast<char>(major));
    out.push_back('\0');
    const std::size_t n = header.size();
    out.push_back(static_cast<char>(n & 0xff));
    out.push_back(static_cast<char>((n >> 8) & 0xff));
    if (major != 1) {
        out.push_back(static_cast<char>((n >> 16) & 0xff));
        out.push_back(static_cast<char>((n >> 24) & 0xff));
    }
    return out + header + data;
}

std::string dict(const std::string& descr, const std::string& shape, const std::string& fortran = "False") {
    return "{'descr': '" + descr + "', 'fortran_order': " + fortran + ", 'shape': " + shape + ", }";
}

template <class T>
std::string values(std::initializer_list<T> v) {
    return std::string(reinterpret_cast<const char*>(std::data(v)), v.size() * sizeof(T));
}

/// 2 frames x 2 points x 3 channels, value = 100 f + 10 p + c.
std::string sequenceF8() {
    std::string out;
    for (int f = 0; f < 2; ++f)
        for (int p = 0; p < 2; ++p)
            for (int c = 0; c < 3; ++c) {
                const double v = 100.0 * f + 10.0 * p + c;
                out.append(reinterpret_cast<const char*>(&v), 8);
            }
    return out;
}

/// Expects an InputError whose message contains the path and every fragment.
template <class F>
void expectInputError(F&& f, const std::string& path, std::initializer_list<std::string> fragments) {
    try {
        f();
        ADD_FAILURE() << "no InputError for " << path;
    } catch (const InputError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(path), std::string::npos) << what;
        for (const auto& fragment : fragments) EXPECT_NE(what.find(fragment), std::string::npos) << what;
    }
}

TEST(NpyRead, Float64CValuesAndLayout) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, npy(dict("<f8", "(2, 2, 3)"), sequenceF8()));
    const auto file = pmsc::readFrames(path);
    EXPECT_EQ(file.dtype, NpyDtype::Float64);
    ASSERT_EQ(file.frames.frames, 2);
    ASSERT_EQ(file.frames.points, 2);
    ASSERT_EQ(file.frames.channels, 3);
    for (int f = 0; f < 2; ++f)
        for (int p = 0; p < 2; ++p)
            for (int c = 0; c < 3; ++c) EXPECT_EQ(file.frames.frame(f)[p * 3 + c], 100.0 * f + 10.0 * p + c);
}

TEST(NpyRead, Float32IsWidenedAndRemembered) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, npy(dict("<f4", "(1, 2, 1)"), values<float>({0.1f, -3.5f})));
    const auto file = pmsc::readFrames(path);
    EXPECT_EQ(file.dtype, NpyDtype::Float32);
    EXPECT_EQ(file.frames.values[0], static_cast<double>(0.1f));
    EXPECT_EQ(file.frames.values[1], -3.5);
}

TEST(NpyRead, AcceptsVersions2And3AndDoubleQuotesAndAnyKeyOrder) {
    TempDir dir;
    const auto v2 = dir.file("v2.npy");
    writeBytes(v2, npy(dict("<f8", "(2, 2, 3)"), sequenceF8(), 2));
    EXPECT_EQ(pmsc::readNpyInfo(v2).majorVersion, 2);
    EXPECT_EQ(pmsc::readFrames(v2).frames.values[11], 112.0);
    const auto v3 = dir.file("v3.npy");
    writeBytes(v3,
               npy("{\"shape\": (2,2,3), \"fortran_order\": False, \"descr\": \"<f8\"}", sequenceF8(), 3));
    EXPECT_EQ(pmsc::readNpyInfo(v3).majorVersion, 3);
    EXPECT_EQ(pmsc::readFrames(v3).frames.values[11], 112.0);
}

TEST(NpyRead, ReadsAFrameRangeOnly) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, npy(dict("<f8", "(2, 2, 3)"), sequenceF8()));
    const auto second = pmsc::readFrameRange(path, 1, 1);
    ASSERT_EQ(second.frames.frames, 1);
    EXPECT_EQ(second.frames.values[0], 100.0);
    EXPECT_EQ(second.frames.values[5], 112.0);
    expectInputError([&] { pmsc::readFrameRange(path, 1, 2); }, path, {"[1, 3)", "2 frames"});
    expectInputError([&] { pmsc::readFrameRange(path, -1, 1); }, path, {"not within"});
    expectInputError([&] { pmsc::readFrameRange(path, 0, 0); }, path, {"not within"});
}

TEST(NpyRead, FrameRangeChecksOnlyTheFramesItReadsButTheWholeFileLength) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    std::string data = sequenceF8();
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::memcpy(data.data() + 8 * 7, &nan, 8);  // frame 1, point 0, channel 1
    writeBytes(path, npy(dict("<f8", "(2, 2, 3)"), data));
    EXPECT_EQ(pmsc::readFrameRange(path, 0, 1).frames.values[5], 12.0);
    expectInputError([&] { pmsc::readFrameRange(path, 1, 1); }, path, {"NaN at frame 1, point 0, channel 1"});
    writeBytes(path, npy(dict("<f8", "(2, 2, 3)"), sequenceF8().substr(0, 90)));
    expectInputError([&] { pmsc::readFrameRange(path, 0, 1); }, path, {"truncated"});
}

TEST(NpyMapped, ReadsWhatReadFramesReadsInBothDtypesAndVersions) {
    TempDir dir;
    const auto f8 = dir.file("f8.npy"), f4 = dir.file("f4.npy");
    writeBytes(f8, npy(dict("<f8", "(2, 2, 3)"), sequenceF8(), 2));
    writeBytes(f4, npy(dict("<f4", "(1, 2, 1)"), values<float>({0.1f, -3.5f})));
    const pmsc::MappedFrames m8(f8), m4(f4);
    EXPECT_EQ(m8.info().dtype, NpyDtype::Float64);
    EXPECT_EQ(m8.info().frames, 2);
    EXPECT_EQ(m4.info().dtype, NpyDtype::Float32);
    const auto all = pmsc::readFrames(f8);
    double frame[6];
    for (pmsc::Index f = 0; f < 2; ++f) {
        m8.readFrame(f, frame);
        for (int i = 0; i < 6; ++i) EXPECT_EQ(frame[i], all.frames.frame(f)[i]);
    }
    const pmsc::Index some[] = {1, 0, 1};
    double picked[9];
    m8.read(1, some, picked);
    EXPECT_EQ(picked[0], 110.0);
    EXPECT_EQ(picked[2], 112.0);
    EXPECT_EQ(picked[3], 100.0);
    EXPECT_EQ(picked[8], 112.0);
    double two[2];
    m4.readFrame(0, two);
    EXPECT_EQ(two[0], static_cast<double>(0.1f));
    EXPECT_EQ(two[1], -3.5);
    EXPECT_THROW(m8.readFrame(2, frame), std::out_of_range);
    EXPECT_THROW(m8.readFrame(-1, frame), std::out_of_range);
    const pmsc::Index outside[] = {2};
    EXPECT_THROW(m8.read(0, outside, picked), std::out_of_range);
}

TEST(NpyMapped, ChecksEveryValueAcrossChunksAndRejectsWhatReadFramesRejects) {
    TempDir dir;
    // 3 frames x 30,000 points x 3: 270,000 values, more than the 65,536 checked at a time.
    FrameSet big(3, 30000, 3);
    for (std::size_t i = 0; i < big.values.size(); ++i)
        big.values[i] = std::sin(0.001 * static_cast<double>(i));
    const auto good = dir.file("good.npy");
    pmsc::writeFrames(good, big, NpyDtype::Float32);
    const pmsc::MappedFrames m(good);
    std::vector<double> frame(90000);
    m.readFrame(2, frame.data());
    EXPECT_EQ(frame[89999], static_cast<double>(static_cast<float>(big.values.back())));

    big.values[2 * 90000 + 3 * 29999 + 1] = std::numeric_limits<double>::infinity();  // in the last chunk
    const auto inf = dir.file("inf.npy");
    pmsc::writeFrames(inf, big, NpyDtype::Float64);
    expectInputError([&] { pmsc::MappedFrames bad(inf); }, inf, {"+Inf at frame 2, point 29999, channel 1"});

    const auto missing = dir.file("missing.npy");
    expectInputError([&] { pmsc::MappedFrames bad(missing); }, missing, {"no such file"});
    const auto truncated = dir.file("truncated.npy");
    writeBytes(truncated, npy(dict("<f8", "(2, 2, 3)"), sequenceF8().substr(0, 95)));
    expectInputError([&] { pmsc::MappedFrames bad(truncated); }, truncated, {"truncated data"});
    const auto empty = dir.file("empty.npy");
    writeBytes(empty, "");
    EXPECT_THROW(pmsc::MappedFrames bad(empty), InputError);
    EXPECT_THROW(pmsc::MappedFrames bad(dir.path().string()), InputError);
}

TEST(NpyReadBad, MissingFile) {
    TempDir dir;
    const auto path = dir.file("nope.npy");
    expectInputError([&] { pmsc::readFrames(path); }, path, {"no such file"});
}

TEST(NpyReadBad, Folder) {
    TempDir dir;
    const auto path = dir.path().string();
    expectInputError([&] { pmsc::readFrames(path); }, path, {"folder"});
}

TEST(NpyReadBad, EmptyAndTinyFiles) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, "");
    expectInputError([&] { pmsc::readFrames(path); }, path, {"not a .npy file"});
    writeBytes(path, std::string("\x93NUMPY\x01\x00\x50", 9));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"truncated .npy header"});
}

TEST(NpyReadBad, BadMagic) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    std::string bytes = npy(dict("<f8", "(2, 2, 3)"), sequenceF8());
    bytes[1] = 'M';
    writeBytes(path, bytes);
    expectInputError([&] { pmsc::readFrames(path); }, path, {"bad magic"});
}

TEST(NpyReadBad, UnsupportedFormatVersion) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    std::string bytes = npy(dict("<f8", "(2, 2, 3)"), sequenceF8());
    bytes[6] = 4;
    writeBytes(path, bytes);
    expectInputError([&] { pmsc::readFrames(path); }, path, {"version 4.0"});
}

TEST(NpyReadBad, HeaderLengthBeyondTheFile) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    std::string bytes = npy(dict("<f8", "(2, 2, 3)"), "", 2);
    bytes[11] = 0x10;  // 256 MiB header in a 128-byte file
    writeBytes(path, bytes);
    expectInputError([&] { pmsc::readFrames(path); }, path, {"header"});
}

TEST(NpyReadBad, MalformedHeaders) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    for (const std::string& d :
         {std::string("not a dict"), std::string("{'descr': '<f8', 'shape': (2, 2, 3)}"),
          std::string("{'descr': '<f8', 'fortran_order': Maybe, 'shape': (2, 2, 3)}"),
          std::string("{'descr': '<f8', 'fortran_order': False, 'shape': (2, x, 3)}"),
          std::string("{'descr': '<f8', 'fortran_order': False, 'shape': (2, 2, 3), 'x': 1}"),
          std::string("{'descr': '<f8', 'fortran_order': False, 'shape': (2, 2, 3)"),
          std::string("{'descr: '<f8'")}) {
        writeBytes(path, npy(d, sequenceF8()));
        expectInputError([&] { pmsc::readFrames(path); }, path, {"header"});
    }
}

TEST(NpyReadBad, UnsupportedDtypesAreNamed) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    for (const std::string descr : {"<i4", "<f2", ">f8", "<c16", "|u1"}) {
        writeBytes(path, npy(dict(descr, "(1, 1, 1)"), std::string(16, '\0')));
        expectInputError([&] { pmsc::readFrames(path); }, path, {"unsupported dtype '" + descr + "'"});
    }
    writeBytes(path, npy("{'descr': [('x', '<f8')], 'fortran_order': False, 'shape': (1, 1, 1), }",
                         std::string(8, '\0')));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"unsupported dtype"});
}

TEST(NpyReadBad, FortranOrder) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, npy(dict("<f8", "(2, 2, 3)", "True"), sequenceF8()));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"fortran_order is True"});
}

TEST(NpyReadBad, WrongRankShowsTheShape) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, npy(dict("<f8", "(4, 3)"), sequenceF8().substr(0, 96)));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"shape (4, 3)", "rank 2"});
    writeBytes(path, npy(dict("<f8", "(12,)"), sequenceF8().substr(0, 96)));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"shape (12,)", "rank 1"});
    writeBytes(path, npy(dict("<f8", "(1, 2, 2, 3)"), sequenceF8().substr(0, 96)));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"shape (1, 2, 2, 3)", "rank 4"});
    writeBytes(path, npy(dict("<f8", "()"), sequenceF8().substr(0, 8)));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"shape ()", "rank 0"});
}

TEST(NpyReadBad, ZeroSizeDimensions) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, npy(dict("<f8", "(0, 2, 3)"), ""));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"zero frames"});
    writeBytes(path, npy(dict("<f8", "(2, 0, 3)"), ""));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"zero points"});
    writeBytes(path, npy(dict("<f8", "(2, 2, 0)"), ""));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"zero channels"});
}

TEST(NpyReadBad, HugeShapeDoesNotAllocate) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, npy(dict("<f8", "(4000000000, 4000000000, 3)"), sequenceF8()));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"too large"});
    writeBytes(path, npy(dict("<f8", "(100000, 100000, 3)"), sequenceF8()));
    expectInputError([&] { pmsc::readFrames(path); }, path,
                     {"truncated data", "240000000000 bytes", "has 96"});
    writeBytes(path, npy(dict("<f8", "(99999999999999999999999, 1, 3)"), sequenceF8()));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"overflows"});
}

TEST(NpyReadBad, TruncatedDataSaysExpectedAndActualBytes) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, npy(dict("<f8", "(2, 2, 3)"), sequenceF8().substr(0, 95)));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"truncated data", "needs 96 bytes", "has 95"});
}

TEST(NpyReadBad, TrailingGarbage) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    writeBytes(path, npy(dict("<f8", "(2, 2, 3)"), sequenceF8() + "xyz"));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"trailing garbage", "3 bytes"});
}

TEST(NpyReadBad, NonFiniteValuesNameFramePointChannel) {
    TempDir dir;
    const auto path = dir.file("a.npy");
    const struct {
        double value;
        std::size_t index;
        const char* expected;
    } cases[] = {
        {std::numeric_limits<double>::quiet_NaN(), 10, "NaN at frame 1, point 1, channel 1"},
        {std::numeric_limits<double>::infinity(), 2, "+Inf at frame 0, point 0, channel 2"},
        {-std::numeric_limits<double>::infinity(), 3, "-Inf at frame 0, point 1, channel 0"},
    };
    for (const auto& c : cases) {
        std::string data = sequenceF8();
        std::memcpy(data.data() + 8 * c.index, &c.value, 8);
        writeBytes(path, npy(dict("<f8", "(2, 2, 3)"), data));
        expectInputError([&] { pmsc::readFrames(path); }, path, {c.expected});
    }
    // float32 too, and the FIRST bad value is the one reported.
    writeBytes(path,
               npy(dict("<f4", "(1, 2, 2)"), values<float>({1.f, 2.f, std::numeric_limits<float>::quiet_NaN(),
                                                            std::numeric_limits<float>::infinity()})));
    expectInputError([&] { pmsc::readFrames(path); }, path, {"NaN at frame 0, point 1, channel 0"});
}

TEST(NpyWrite, RoundTripFloat64IsExact) {
    TempDir dir;
    const auto path = dir.file("out.npy");
    FrameSet set(3, 5, 3);
    for (std::size_t i = 0; i < set.values.size(); ++i) set.values[i] = std::sin(1.0 + i) * 1e3 / 7.0;
    pmsc::writeFrames(path, set, NpyDtype::Float64);
    const auto back = pmsc::readFrames(path);
    EXPECT_EQ(back.dtype, NpyDtype::Float64);
    EXPECT_EQ(back.frames.frames, 3);
    EXPECT_EQ(back.frames.points, 5);
    EXPECT_EQ(back.frames.channels, 3);
    EXPECT_EQ(back.frames.values, set.values);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"out.npy"});
}

TEST(NpyWrite, RoundTripFloat32RoundsToNearest) {
    TempDir dir;
    const auto path = dir.file("out.npy");
    FrameSet set(2, 4, 1);
    for (std::size_t i = 0; i < set.values.size(); ++i) set.values[i] = 1.0 / (3.0 + i);
    pmsc::writeFrames(path, set, NpyDtype::Float32);
    const auto back = pmsc::readFrames(path);
    EXPECT_EQ(back.dtype, NpyDtype::Float32);
    for (std::size_t i = 0; i < set.values.size(); ++i)
        EXPECT_EQ(back.frames.values[i], static_cast<double>(static_cast<float>(set.values[i])));
}

TEST(NpyWrite, HeaderIsNumpyCompatible) {
    TempDir dir;
    const auto path = dir.file("out.npy");
    FrameSet set(2, 2, 3);
    set.values.assign(12, 0.0);
    pmsc::writeFrames(path, set, NpyDtype::Float64);
    const std::string bytes = pmsc::test::readBytes(path);
    ASSERT_GE(bytes.size(), 64u);
    EXPECT_EQ(bytes.substr(0, 8), std::string("\x93NUMPY\x01\x00", 8));
    const std::size_t headerLength =
        static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8);
    EXPECT_EQ((10 + headerLength) % 64, 0u);  // data aligned as NumPy does
    const std::string header = bytes.substr(10, headerLength);
    EXPECT_EQ(header.back(), '\n');
    EXPECT_NE(header.find("'descr': '<f8'"), std::string::npos);
    EXPECT_NE(header.find("'fortran_order': False"), std::string::npos);
    EXPECT_NE(header.find("'shape': (2, 2, 3)"), std::string::npos);
    EXPECT_EQ(bytes.size(), 10 + headerLength + 96);
}

TEST(NpyWrite, ReplacesAnExistingFileWhole) {
    TempDir dir;
    const auto path = dir.file("out.npy");
    writeBytes(path, "old contents");
    FrameSet set(1, 1, 1);
    set.values[0] = 42;
    pmsc::writeFrames(path, set, NpyDtype::Float64);
    EXPECT_EQ(pmsc::readFrames(path).frames.values[0], 42.0);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"out.npy"});
}

TEST(NpyWrite, MissingFolderIsAnIoErrorAndLeavesNothing) {
    TempDir dir;
    FrameSet set(1, 1, 1);
    EXPECT_THROW(pmsc::writeFrames(dir.file("no/such/folder/out.npy"), set, NpyDtype::Float64),
                 pmsc::IoError);
    EXPECT_TRUE(dir.entries().empty());
}

TEST(NpyWrite, FailedRenameRemovesTheTemporaryFile) {
    TempDir dir;
    std::filesystem::create_directory(dir.file("taken"));
    std::filesystem::create_directory(dir.file("taken/child"));  // rename onto a non-empty folder fails
    FrameSet set(1, 1, 1);
    try {
        pmsc::writeFrames(dir.file("taken"), set, NpyDtype::Float64);
        ADD_FAILURE() << "no IoError";
    } catch (const pmsc::IoError& e) {
        EXPECT_NE(std::string(e.what()).find("taken"), std::string::npos) << e.what();
    }
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"taken"});
}

TEST(NpyWrite, FrameWriterAcceptsFramesInAnyOrderAndLeavesNothingUntilCommit) {
    TempDir dir;
    const auto path = dir.file("out.npy");
    FrameSet set(3, 2, 2);
    for (std::size_t i = 0; i < set.values.size(); ++i) set.values[i] = static_cast<double>(i);
    {
        pmsc::NpyFrameWriter writer(path, 3, 2, 2, NpyDtype::Float64);
        writer.writeFrame(2, set.frame(2));
        writer.writeFrame(0, set.frame(0));
        EXPECT_THROW(writer.writeFrame(3, set.frame(0)), std::out_of_range);
        EXPECT_FALSE(std::filesystem::exists(path));
    }  // destroyed without commit
    EXPECT_TRUE(dir.entries().empty());

    pmsc::NpyFrameWriter writer(path, 3, 2, 2, NpyDtype::Float64);
    for (int f : {1, 2, 0}) writer.writeFrame(f, set.frame(f));
    writer.commit();
    EXPECT_EQ(pmsc::readFrames(path).frames.values, set.values);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"out.npy"});
}

TEST(NpyWrite, RejectsInconsistentFrameSets) {
    TempDir dir;
    FrameSet set(2, 2, 2);
    set.values.pop_back();
    EXPECT_THROW(pmsc::writeFrames(dir.file("x.npy"), set, NpyDtype::Float64), std::invalid_argument);
    EXPECT_THROW(pmsc::NpyFrameWriter(dir.file("x.npy"), 0, 2, 2, NpyDtype::Float64), std::invalid_argument);
    EXPECT_TRUE(dir.entries().empty());
}

}  // namespace
