#include "pmsc/AtomicFile.h"
#include "pmsc/Errors.h"

#include "tests/common/TempDir.h"

#include <gtest/gtest.h>

#include <csignal>
#include <ctime>
#include <string>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <utime.h>

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

TEST(AtomicFile, TemporaryNamesTellWhoseTheyAreAndWhetherTheWriterLives) {
    TempDir dir;
    pmsc::AtomicFile mine(dir.file("frame.npy"));
    const std::string tag = pmsc::temporaryTag();
    EXPECT_NE(mine.temporaryPath().find(".tmp-" + tag), std::string::npos) << mine.temporaryPath();
    EXPECT_FALSE(pmsc::temporaryMayBeInUse(mine.temporaryPath())) << "our own: the caller decides";

    const std::string host = tag.substr(tag.find('@') + 1, tag.size() - tag.find('@') - 2);
    const auto touch = [&](const std::string& name) {
        pmsc::test::writeBytes(dir.file(name), "x");
        return dir.file(name);
    };
    // A live process of this host (a child that waits), then the same pid once it has ended.
    const pid_t child = ::fork();
    ASSERT_GE(child, 0);
    if (child == 0) {
        ::pause();
        ::_exit(0);
    }
    const std::string live = touch("frame.npy.tmp-" + std::to_string(child) + "@" + host + "-Ab3dE9");
    EXPECT_TRUE(pmsc::temporaryMayBeInUse(live));
    ::kill(child, SIGKILL);
    ::waitpid(child, nullptr, 0);
    EXPECT_FALSE(pmsc::temporaryMayBeInUse(live)) << "its writer has ended";

    // Another host: in use while recent, abandoned once older than the limit.
    const std::string other = touch("frame.npy.tmp-4242@some-other-node.farm-Zz9yY8");
    EXPECT_TRUE(pmsc::temporaryMayBeInUse(other));
    const utimbuf old{std::time(nullptr) - 3600, std::time(nullptr) - 3600};
    ASSERT_EQ(::utime(other.c_str(), &old), 0);
    EXPECT_FALSE(pmsc::temporaryMayBeInUse(other));

    // Names without a tag, or with a malformed one, are not in use.
    EXPECT_FALSE(pmsc::temporaryMayBeInUse(touch("frame.npy.tmp-Qw12Er")));
    EXPECT_FALSE(pmsc::temporaryMayBeInUse(touch("frame.npy.tmp-12x@" + host + "-Qw12Er")));
    EXPECT_FALSE(pmsc::temporaryMayBeInUse(touch("frame.npy.tmp-@" + host + "-Qw12Er")));
    EXPECT_FALSE(pmsc::temporaryMayBeInUse(dir.file("frame.npy.tmp-1@other-node-gone00"))) << "no such file";
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
