#include "evaluators/scene/Image.h"

#include "pmsc/Errors.h"

#include <gtest/gtest.h>
#include <png.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

namespace pmsc::scene {
namespace {

std::string tempPath(const std::string& name) {
    return (std::filesystem::temp_directory_path() /
            ("pmsc_cornell_img_" + std::to_string(::getpid()) + "_" + name))
        .string();
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
    EXPECT_EQ(std::string(sig + 1, 3), "PNG");
    // Decoded by libpng: the size, and the tone map (x / (1 + x), sRGB): 0 -> 0, 2 -> 2/3 -> 213,
    // 20 -> 20/21 -> 250.
    png_image back;
    std::memset(&back, 0, sizeof back);
    back.version = PNG_IMAGE_VERSION;
    ASSERT_NE(png_image_begin_read_from_file(&back, path.c_str()), 0) << back.message;
    back.format = PNG_FORMAT_RGB;
    std::vector<unsigned char> rgb(PNG_IMAGE_SIZE(back));
    ASSERT_NE(png_image_finish_read(&back, nullptr, rgb.data(), 0, nullptr), 0) << back.message;
    std::filesystem::remove(path);
    EXPECT_EQ(back.width, 12u);
    EXPECT_EQ(back.height, 2u);
    EXPECT_EQ(rgb[3 * (1 * 12 + 0)], 0);
    EXPECT_EQ(rgb[3 * (1 * 12 + 5)], 213);
    EXPECT_EQ(rgb[3 * (1 * 12 + 9)], 250);
    EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
    EXPECT_THROW(writePng("/nonexistent-folder-pmsc/a.png", s, 1.0f), IoError);
    const Image tall(2, 5);
    EXPECT_THROW(sideBySide({&a, &tall}), std::invalid_argument);
}

}  // namespace
}  // namespace pmsc::scene
