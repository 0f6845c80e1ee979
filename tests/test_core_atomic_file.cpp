// Atomic, durable file writes (core/atomic_file.hpp) and file identity (core/file_identity.hpp):
// nothing visible before the commit, a killed writer's temporary removed, links followed, mode
// kept, write-protected files and over-long names refused up front, one file under two
// spellings recognised.
#include <catch2/catch.hpp>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/file_identity.hpp"
#include "support/files.hpp"

using namespace sbptt;
using sbptt::testing::file_text;
using sbptt::testing::fresh_directory;
namespace fs = std::filesystem;

namespace {

long entries(const fs::path& dir) {
  return std::distance(fs::directory_iterator(dir), fs::directory_iterator());
}

}  // namespace

TEST_CASE("atomic file: nothing is in the directory until the commit", "[core]") {
  // So a process killed while writing leaves no temporary file behind.
  const fs::path dir = fresh_directory("invisible");
  {
    AtomicFile file((dir / "out.txt").string());
    file.write(std::string(1 << 20, 'x'));
    CHECK(entries(dir) == 0);
  }  // destroyed uncommitted: discarded
  CHECK(entries(dir) == 0);
  AtomicFile file((dir / "out.txt").string());
  file.write("done\n");
  file.commit();
  CHECK(entries(dir) == 1);
  CHECK(file_text(dir / "out.txt") == "done\n");
}

TEST_CASE("atomic file: a killed writer's temporary goes at the next write of its file",
          "[core]") {
  // A SIGKILL between naming the finished temporary and the rename leaves <name>.tmp.<pid>.<n>.
  const fs::path dir = fresh_directory("leftover");
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  REQUIRE(child > 0);
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);  // reaped: no process has this pid now
  const std::string dead = std::to_string(child), alive = std::to_string(::getppid());
  const std::string own = std::to_string(::getpid());
  const std::vector<std::string> stale{"out.txt.tmp." + dead + ".0",
                                       "out.txt.tmp." + dead + ".17"};
  const std::vector<std::string> kept{
      "out.txt.tmp." + alive + ".0",     // its writer may still rename it
      "out.txt.tmp." + own + ".0",       // this process's own, maybe in flight
      "other.txt.tmp." + dead + ".0",    // another file's
      "out.txt.tmp." + dead + ".0.bak",  // not a temporary's name
      "out.txt.tmp." + dead,
      "out.txt.tmp.x" + dead + ".0"};
  // A writer whose pid this process does not see (another pid namespace, another NFS client)
  // still holds the lock on its temporary.
  const std::string locked = "out.txt.tmp." + dead + ".5";
  for (const auto& name : stale) std::ofstream(dir / name) << "stale\n";
  for (const auto& name : kept) std::ofstream(dir / name) << "kept\n";
  std::ofstream(dir / locked) << "kept\n";
  const int writer = ::open((dir / locked).c_str(), O_RDONLY | O_CLOEXEC);
  REQUIRE(writer >= 0);
  REQUIRE(::flock(writer, LOCK_EX | LOCK_NB) == 0);
  write_file_atomically((dir / "out.txt").string(), "new\n");
  ::close(writer);
  CHECK(file_text(dir / "out.txt") == "new\n");
  for (const auto& name : stale) CHECK_FALSE(fs::exists(dir / name));
  for (const auto& name : kept) CHECK(file_text(dir / name) == "kept\n");
  CHECK(file_text(dir / locked) == "kept\n");
}

TEST_CASE("atomic file: a symbolic link is followed, not replaced", "[core]") {
  const fs::path dir = fresh_directory("link");
  fs::create_directories(dir / "real");
  std::ofstream(dir / "real" / "log.csv") << "old\n";
  fs::create_symlink(dir / "real" / "log.csv", dir / "link.csv");
  write_file_atomically((dir / "link.csv").string(), "new\n");
  CHECK(fs::is_symlink(fs::symlink_status(dir / "link.csv")));
  CHECK(file_text(dir / "real" / "log.csv") == "new\n");
  CHECK(entries(dir / "real") == 1);
}

TEST_CASE("atomic file: an existing file keeps its permission bits", "[core]") {
  const fs::path dir = fresh_directory("mode");
  std::ofstream(dir / "p.txt") << "old\n";
  REQUIRE(::chmod((dir / "p.txt").c_str(), 0640) == 0);
  write_file_atomically((dir / "p.txt").string(), "new\n");
  struct stat info {};
  REQUIRE(::stat((dir / "p.txt").c_str(), &info) == 0);
  CHECK((info.st_mode & 07777) == 0640);
  CHECK(file_text(dir / "p.txt") == "new\n");
}

TEST_CASE("atomic file: a failed rename names the temporary, the path and the reason",
          "[core]") {
  const fs::path dir = fresh_directory("rename");
  fs::create_directories(dir / "out.csv");  // a directory: a file cannot be renamed over it
  const std::string path = (dir / "out.csv").string();
  CHECK_THROWS_WITH(write_file_atomically(path, "new\n"),
                    Catch::Contains("cannot rename '" + path + ".tmp.") &&
                        Catch::Contains("' to '" + path + "': ") &&
                        Catch::Contains(std::strerror(EISDIR)));
  CHECK(entries(dir) == 1);  // the temporary is gone
}

TEST_CASE("atomic file: a special file is refused and left as it was", "[core]") {
  // Renamed over, a FIFO or a device (think /dev/null) would become a regular file.
  const fs::path dir = fresh_directory("special");
  const fs::path fifo = dir / "pipe";
  REQUIRE(::mkfifo(fifo.c_str(), 0666) == 0);
  CHECK_THROWS_WITH(write_file_atomically(fifo.string(), "new\n"),
                    Catch::Contains("'" + fifo.string() + "' exists and is a special file"));
  CHECK(fs::is_fifo(fifo));
  CHECK(entries(dir) == 1);  // no temporary left
}

namespace {

/// Runs `body` as the unprivileged user 65534 (nobody) in a child process when this test runs
/// as root, who may write anything, else in this process; true if it returned true.
template <class Body>
bool as_unprivileged_user(const fs::path& dir, Body body) {
  if (::geteuid() != 0) return body();
  for (const auto& entry : fs::recursive_directory_iterator(dir))
    REQUIRE(::chown(entry.path().c_str(), 65534, 65534) == 0);
  REQUIRE(::chown(dir.c_str(), 65534, 65534) == 0);
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    const bool dropped = ::setgid(65534) == 0 && ::setuid(65534) == 0 && ::geteuid() == 65534;
    ::_exit(dropped && body() ? 0 : 1);
  }
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  return WIFEXITED(status) && WEXITSTATUS(status) == 0;
}

}  // namespace

TEST_CASE("atomic file: a write-protected file is refused and left as it was", "[core]") {
  // The rule is about a user who may not write the file; as root, the check runs as nobody.
  const fs::path dir = fresh_directory("protected");
  std::ofstream(dir / "p.txt") << "keep\n";
  REQUIRE(::chmod((dir / "p.txt").c_str(), 0444) == 0);
  const std::string path = (dir / "p.txt").string();
  CHECK(as_unprivileged_user(dir, [&] {
    try {
      check_output_path(path, "--save-params");
      return false;
    } catch (const IoError& e) {
      const std::string what = e.what();
      return what.find("--save-params") != std::string::npos &&
             what.find("write-protected") != std::string::npos;
    }
  }));
  CHECK(as_unprivileged_user(dir, [&] {
    try {
      write_file_atomically(path, "new\n");
      return false;
    } catch (const IoError&) {
      return true;
    }
  }));
  CHECK(file_text(dir / "p.txt") == "keep\n");
  CHECK(entries(dir) == 1);
}

TEST_CASE("atomic file: an append-only file or directory (chattr +a) is refused up front",
          "[core]") {
  // Neither can be renamed over, so a run would lose its file at the end, after the work.
  const fs::path dir = fresh_directory("append_only");
  const fs::path file = dir / "p.txt";
  std::ofstream(file) << "keep\n";
  struct Attribute {  // chattr +a on `path` while in scope
    fs::path path;
    bool set = std::system(("chattr +a '" + path.string() + "' 2>/dev/null").c_str()) == 0;
    ~Attribute() {
      if (set) (void)std::system(("chattr -a '" + path.string() + "'").c_str());
    }
  };
  {
    const Attribute append_only{file};
    if (!append_only.set) {
      WARN("chattr +a failed (not root, or the file system has no such attribute): skipped");
      return;
    }
    CHECK_THROWS_WITH(check_output_path(file.string(), "--save-params"),
                      Catch::Contains("--save-params '" + file.string() + "'") &&
                          Catch::Contains("the file is append-only (chattr +a)"));
    CHECK_THROWS_AS(write_file_atomically(file.string(), "new\n"), IoError);
  }
  CHECK(file_text(file) == "keep\n");
  CHECK_NOTHROW(check_output_path(file.string(), "--save-params"));
  const Attribute append_only{dir};
  REQUIRE(append_only.set);
  for (const fs::path& path : {file, dir / "new.txt"}) {
    INFO(path);
    CHECK_THROWS_WITH(check_output_path(path.string(), "--csv"),
                      Catch::Contains("--csv '" + path.string() + "'") &&
                          Catch::Contains("directory '" + dir.string() + "' is append-only"));
    // Without the check first, the write itself: it named its temporary, could neither rename
    // nor remove it there, and left it behind.
    CHECK_THROWS_WITH(write_file_atomically(path.string(), "new\n"),
                      Catch::Contains("'" + path.string() + "'") &&
                          Catch::Contains("append-only"));
  }
  CHECK(entries(dir) == 1);
}

TEST_CASE("atomic file: names too long with the temporary suffix are refused up front", "[core]") {
  const fs::path dir = fresh_directory("long");
  const std::string ok(200, 'a'), too_long(234, 'b');
  CHECK_NOTHROW(check_output_path((dir / ok).string(), "--csv"));
  CHECK_THROWS_WITH(check_output_path((dir / too_long).string(), "--csv"),
                    Catch::Contains("--csv") && Catch::Contains("234 bytes") &&
                        Catch::Contains("limit of 255"));
  CHECK_THROWS_WITH(check_output_path("", "--csv"), Catch::Contains("--csv: the path is empty"));
}

TEST_CASE("file identity: one file under two spellings is caught", "[core]") {
  const fs::path dir = fresh_directory("identity");
  std::ofstream(dir / "a.txt") << "1\n";
  fs::create_hard_link(dir / "a.txt", dir / "hard.txt");
  fs::create_symlink(dir / "a.txt", dir / "soft.txt");
  const std::string a = (dir / "a.txt").string();
  for (const std::string& other : {(dir / "hard.txt").string(), (dir / "soft.txt").string(),
                                   (dir / "." / "a.txt").string()}) {
    CHECK_THROWS_WITH(require_distinct_files({{"--init-params", a, false},
                                             {"--save-params", other, true}}),
                      Catch::Contains("are the same file"));
    CHECK_NOTHROW(require_distinct_files({{"--init-params", a, false},
                                          {"--init-states", other, false}}));
  }
  CHECK_THROWS_WITH(require_distinct_files({{"--csv", (dir / "new.csv").string(), true},
                                           {"--save-params", (dir / ".." / "identity" / "new.csv").string(), true}}),
                    Catch::Contains("--csv") && Catch::Contains("--save-params"));
  CHECK_NOTHROW(require_distinct_files({{"--csv", (dir / "x.csv").string(), true},
                                        {"--save-params", (dir / "y.txt").string(), true}}));
}
