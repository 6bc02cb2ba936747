// Output on a full disk (issue 20): the run stops with exit 1, a message naming the file and
// "disk full?", and leaves only complete files: stats.csv ends with a complete row (one per
// frame written), frames are whole, no temporary files, the PC2 header counts only whole samples.
// Two ways to fill the disk: a 16 KiB per-file size limit (setrlimit RLIMIT_FSIZE with SIGXFSZ
// ignored; works everywhere), and a real ENOSPC from a small tmpfs mounted in a private user and
// mount namespace (`unshare -rm`; skipped with a message where namespaces are not allowed).
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "cli_run.hpp"

namespace fs = std::filesystem;

namespace {

const std::string kScene = std::string(LOOM_SOURCE_DIR) + "/scenes/hanging_10x10_k2000.yaml";

struct Outcome {
  int code = -1;
  std::string err;
};

/// loom run with a per-file size limit of `limit` bytes (SIGXFSZ ignored, so writes fail with
/// EFBIG as they would with ENOSPC); stderr captured.
Outcome run_with_file_size_limit(const std::vector<std::string>& args, rlim_t limit, const fs::path& err_file) {
  std::vector<std::string> all = {LOOM_EXE, "run", kScene};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid == 0) {
    std::FILE* e = std::freopen(err_file.c_str(), "w", stderr);
    (void)e;
    std::signal(SIGXFSZ, SIG_IGN);  // an ignored disposition survives exec
    struct rlimit rl {limit, limit};
    setrlimit(RLIMIT_FSIZE, &rl);
    execv(argv[0], argv.data());
    _exit(127);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  Outcome o;
  o.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream in(err_file);
  std::stringstream ss;
  ss << in.rdbuf();
  o.err = ss.str();
  return o;
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Every row of stats.csv complete: ends with '\n' and has the header's field count. Returns rows.
int check_stats_complete(const fs::path& stats) {
  const std::string s = slurp(stats);
  EXPECT_FALSE(s.empty());
  if (s.empty()) return 0;
  EXPECT_EQ(s.back(), '\n') << "stats.csv ends mid-row";
  std::istringstream in(s);
  std::string line;
  std::getline(in, line);
  const auto fields = std::count(line.begin(), line.end(), ',');
  int rows = 0;
  while (std::getline(in, line)) {
    EXPECT_EQ(std::count(line.begin(), line.end(), ','), fields) << "incomplete row " << rows << ": " << line;
    ++rows;
  }
  return rows;
}

int count_with(const fs::path& dir, const std::string& part) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(part) != std::string::npos) ++n;
  return n;
}

}  // namespace

TEST(DiskFull, StatsOnlyRunStopsWithExit1AndCompleteRows) {
  const fs::path d = loom_cli_test::scratch_dir("loom_diskfull_", "stats");
  const Outcome o = run_with_file_size_limit({"--out", (d / "run").string(), "--quiet", "--set", "frames=2000",
                                              "--set", "integrator.substeps=1", "--set", "output.obj=false"},
                                             16 * 1024, d / "err.txt");
  EXPECT_EQ(o.code, 1) << o.err;
  EXPECT_NE(o.err.find("stats.csv"), std::string::npos) << o.err;
  EXPECT_NE(o.err.find("disk full?"), std::string::npos) << o.err;
  const int rows = check_stats_complete(d / "run" / "stats.csv");
  EXPECT_GT(rows, 10);    // it wrote rows until the limit
  EXPECT_LT(rows, 2001);  // and stopped there
  EXPECT_EQ(count_with(d / "run", ".tmp"), 0);
}

TEST(DiskFull, PointCacheCountsOnlyWholeSamples) {
  const fs::path d = loom_cli_test::scratch_dir("loom_diskfull_", "pc2");
  const Outcome o = run_with_file_size_limit({"--out", (d / "run").string(), "--quiet", "--set", "frames=200",
                                              "--set", "integrator.substeps=1", "--set", "output.obj=false",
                                              "--set", "output.stats=false", "--set", "output.pc2=true"},
                                             16 * 1024, d / "err.txt");
  EXPECT_EQ(o.code, 1) << o.err;
  EXPECT_NE(o.err.find("run.pc2"), std::string::npos) << o.err;
  const std::string pc2 = slurp(d / "run" / "run.pc2");
  ASSERT_GE(pc2.size(), 32u);
  std::int32_t points = 0, samples = 0;
  std::memcpy(&points, pc2.data() + 16, 4);
  std::memcpy(&samples, pc2.data() + 28, 4);
  EXPECT_EQ(points, 100);
  // 100 points x 12 bytes per sample; the limit allows 13 whole samples after the header.
  EXPECT_EQ(samples, static_cast<std::int32_t>((16 * 1024 - 32) / 1200));
  EXPECT_GE(pc2.size(), 32u + static_cast<std::size_t>(samples) * 1200u);
}

// A real ENOSPC: a 64 KiB tmpfs in a private namespace; OBJ frames and stats. The checks run
// inside the namespace (the tmpfs disappears with it) and print what the test asserts on.
TEST(DiskFull, RealFullDiskKeepsWholeFramesAndMatchingStats) {
  const fs::path d = loom_cli_test::scratch_dir("loom_diskfull_", "tmpfs");
  const std::string mnt = (d / "mnt").string();
  fs::create_directories(mnt);
  const std::string script =
      "mount -t tmpfs -o size=64k tmpfs '" + mnt + "' || exit 77; cd '" + mnt + "' || exit 77; '" LOOM_EXE
      "' run '" + kScene + "' --out run --quiet --set frames=2000 --set integrator.substeps=1 --set output.obj=true; "
      "echo \"rc=$?\"; echo \"frames=$(ls run | grep -c '^frame_.*\\.obj$')\"; "
      "echo \"tmp=$(ls run | grep -c '\\.tmp')\"; echo \"rows=$(($(wc -l < run/stats.csv) - 1))\"; "
      "echo \"stats_ends_in_newline=$(tail -c 1 run/stats.csv | wc -l)\"; "
      "for f in run/frame_*.obj; do echo \"v=$(grep -c '^v ' $f) f=$(grep -c '^f ' $f)\"; done | sort | uniq -c";
  const fs::path script_file = d / "fill.sh";
  std::ofstream(script_file) << script << "\n";
  const auto r = loom_cli_test::run_loom_shell("unshare -rm sh '" + script_file.string() + "'");
  if (r.code == 77 || r.out.find("rc=") == std::string::npos)
    GTEST_SKIP() << "cannot mount a tmpfs in a private namespace here (unshare -rm): " << r.out;
  EXPECT_NE(r.out.find("rc=1"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("disk full?"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("tmp=0"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("stats_ends_in_newline=1"), std::string::npos) << r.out;
  // every frame whole (100 vertices, 162 triangles), one kind of frame only
  EXPECT_NE(r.out.find("v=100 f=162"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("v=", r.out.find("v=100 f=162") + 1), std::string::npos) << r.out;
  // stats rows never ahead of the frames: rows <= frames (frame 0 has a row and a file)
  const auto num = [&](const std::string& key) {
    const auto p = r.out.find(key + "=");
    return p == std::string::npos ? -1 : std::stoi(r.out.substr(p + key.size() + 1));
  };
  EXPECT_GT(num("frames"), 1) << r.out;
  EXPECT_LE(num("rows"), num("frames")) << r.out;
}
