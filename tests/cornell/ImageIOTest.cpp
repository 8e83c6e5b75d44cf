#include "examples/cornell/ImageIO.h"

#include "pmsc/Errors.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace pmsc::cornell {
namespace {

std::string tempPath(const std::string& name) {
    return (std::filesystem::temp_directory_path() / ("pmsc_cornell_img_" + std::to_string(::getpid()) + "_" + name)).string();
}

TEST(ImageIO, PfmRoundTripIsExact) {
    Image img(5, 3);
    for (std::size_t i = 0; i < img.rgb.size(); ++i) img.rgb[i] = 0.1f * static_cast<float>(i) - 0.7f;
    const std::string path = tempPath("a.pfm");
    writePfm(path, img);
    const Image back = readPfm(path);
    std::filesystem::remove(path);
    ASSERT_EQ(back.width, 5);
    ASSERT_EQ(back.height, 3);
    EXPECT_EQ(back.rgb, img.rgb);
}

TEST(ImageIO, PngHasTheSignatureAndSideBySideStacksPanels) {
    Image a(4, 2), b(4, 2);
    b.pixel(1, 1)[0] = 2.0f;
    const Image d = absDifference(a, b, 10.0f);
    EXPECT_FLOAT_EQ(d.pixel(1, 1)[0], 20.0f);
    const Image s = sideBySide({&a, &b, &d});
    EXPECT_EQ(s.width, 12);
    EXPECT_FLOAT_EQ(s.pixel(5, 1)[0], 2.0f);
    const std::string path = tempPath("a.png");
    writePng(path, s, 1.0f);
    std::ifstream f(path, std::ios::binary);
    char sig[8] = {};
    f.read(sig, 8);
    std::filesystem::remove(path);
    EXPECT_EQ(std::string(sig + 1, 3), "PNG");
    EXPECT_THROW(writePng("/nonexistent-folder-pmsc/a.png", s, 1.0f), IoError);
    const Image tall(2, 5);
    EXPECT_THROW(sideBySide({&a, &tall}), std::invalid_argument);
}

}  // namespace
}  // namespace pmsc::cornell
