#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include "TempDir.h"

#include <gtest/gtest.h>

#include <csignal>
#include <string>

#include <sys/resource.h>

namespace {

using pmsc::test::TempDir;

TEST(AtomicFile, NothingAtThePathUntilCommit) {
    TempDir dir;
    const auto path = dir.file("out.bin");
    pmsc::AtomicFile file(path);
    file.write("hello", 5);
    EXPECT_FALSE(std::filesystem::exists(path));
    EXPECT_TRUE(std::filesystem::exists(file.temporaryPath()));
    EXPECT_EQ(std::filesystem::path(file.temporaryPath()).parent_path(),
              dir.path());  // same folder: atomic rename
    file.commit();
    EXPECT_EQ(pmsc::test::readBytes(path), "hello");
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"out.bin"});
}

TEST(AtomicFile, AbandonedOrDestroyedLeavesNoTemporaryFile) {
    TempDir dir;
    {
        pmsc::AtomicFile file(dir.file("a.bin"));
        file.write("x", 1);
    }
    pmsc::AtomicFile file(dir.file("b.bin"));
    file.abandon();
    file.abandon();
    EXPECT_TRUE(dir.entries().empty());
}

TEST(AtomicFile, WriteAtFillsHoles) {
    TempDir dir;
    const auto path = dir.file("out.bin");
    pmsc::AtomicFile file(path);
    file.writeAt(3, "def", 3);
    file.writeAt(0, "abc", 3);
    file.commit();
    EXPECT_EQ(pmsc::test::readBytes(path), "abcdef");
}

TEST(AtomicFile, UnwritableFolderIsAnIoErrorNamingThePath) {
    TempDir dir;
    const auto path = dir.file("missing/out.bin");
    try {
        pmsc::writeFileAtomically(path, "data");
        ADD_FAILURE() << "no IoError";
    } catch (const pmsc::IoError& e) {
        EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
    EXPECT_TRUE(dir.entries().empty());
}

// A write that fails half way (here: the file-size limit, as a full disk would) removes the
// temporary file and keeps the previous file at the path untouched.
TEST(AtomicFile, FailedWriteRemovesTheTemporaryFileAndKeepsTheOldFile) {
    TempDir dir;
    const auto path = dir.file("out.bin");
    pmsc::test::writeBytes(path, "previous");
    rlimit old{};
    ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &old), 0);
    const auto oldHandler = std::signal(SIGXFSZ, SIG_IGN);
    rlimit small = old;
    small.rlim_cur = 4096;
    ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
    bool threw = false;
    try {
        pmsc::writeFileAtomically(path, std::string(100000, 'x'));
    } catch (const pmsc::IoError&) {
        threw = true;
    }
    ::setrlimit(RLIMIT_FSIZE, &old);
    std::signal(SIGXFSZ, oldHandler);
    EXPECT_TRUE(threw);
    EXPECT_EQ(pmsc::test::readBytes(path), "previous");
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"out.bin"});
}

}  // namespace
