// Every example command in README.md runs as printed. The test reads the README's ```sh
// blocks, takes each line that calls loom (./loom, loom, build/bin/loom, under mpirun too),
// and runs it from a scratch folder that links the repository's scenes/, studies/,
// materials/, data/ and scripts/, in order (so `loom render out/x` sees the run before it).
// Only the length changes: `loom run` gets --frames 1 (2 with --resume) and 2 steps per frame,
// `loom study` a copy of its study file with one measurement time, two step levels and a
// coarser reference step.
// The CLI synopsis lines must name commands and flags `loom --help` knows, and the inline
// `--set` example must validate.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

const fs::path kRoot = LOOM_SOURCE_DIR;

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

struct Result {
  int code = -1;
  std::string out;
};

Result shell(const std::string& cmd) {
  Result r;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  std::array<char, 4096> buf{};
  while (fgets(buf.data(), buf.size(), p)) r.out += buf.data();
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::string quote(const std::string& s) { return "'" + s + "'"; }

// The lines of the README's fenced blocks of the given language ("" = no language).
std::vector<std::string> block_lines(const std::string& text, const std::string& lang) {
  std::vector<std::string> out;
  std::istringstream in(text);
  bool inside = false, wanted = false;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("```", 0) == 0) {
      if (!inside) wanted = line.substr(3) == lang;
      inside = !inside;
      continue;
    }
    if (inside && wanted) out.push_back(line);
  }
  return out;
}

std::vector<std::string> words(const std::string& line) {
  std::string s = line;
  // a comment starts at " #" (the examples quote nothing)
  if (const auto c = s.find(" #"); c != std::string::npos) s = s.substr(0, c);
  if (!s.empty() && s[0] == '#') return {};
  std::istringstream in(s);
  std::vector<std::string> w;
  for (std::string t; in >> t;) w.push_back(t);
  return w;
}

bool has_substeps(const fs::path& scene) {
  static const std::regex re(R"(^\s+substeps:)");
  std::ifstream in(scene);
  for (std::string line; std::getline(in, line);)
    if (std::regex_search(line, re)) return true;
  return false;
}

struct Example {
  std::string readme_line;
  std::string command;  // what runs
  std::string skip;     // why it does not run here (empty: it runs)
};

std::vector<Example> examples(const fs::path& work) {
  const std::string readme = slurp(kRoot / "README.md");
  std::vector<Example> out;
  for (const std::string& line : block_lines(readme, "sh")) {
    std::vector<std::string> w = words(line);
    if (w.empty()) continue;
    Example ex;
    ex.readme_line = line;
    std::string env;
    std::size_t k = 0;
    while (k < w.size() && w[k].find('=') != std::string::npos && w[k][0] != '-') env += w[k++] + " ";
    std::vector<std::string> prefix;  // mpirun -n 2 ...
    if (k < w.size() && w[k] == "mpirun") {
      prefix.push_back("mpirun");
      ++k;
      while (k < w.size() && w[k].find("loom") == std::string::npos) prefix.push_back(w[k++]);
      // as root OpenMPI needs these, and 2 ranks on fewer cores --oversubscribe (the README says so)
      env += "OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 ";
      prefix.insert(prefix.begin() + 1, "--oversubscribe");
    }
    if (k >= w.size()) continue;
    const std::string prog = w[k];
    if (prog == "scripts/test.sh") {
      // The suite itself: not run from inside the suite; it must exist and be executable.
      EXPECT_EQ(::access((kRoot / prog).c_str(), X_OK), 0) << line;
      continue;
    }
    if (prog != "./loom" && prog != "loom" && prog != "build/bin/loom") {
      ADD_FAILURE() << "README example runs something the test does not know: " << line;
      continue;
    }
    if (prog == "./loom") {
      EXPECT_EQ(::access((kRoot / "loom").c_str(), X_OK), 0) << "./loom is not executable";
    }
    std::vector<std::string> args(w.begin() + static_cast<std::ptrdiff_t>(k) + 1, w.end());
    if (args.empty()) continue;
    const std::string cmd = args[0];
    if (cmd == "run") {
      const bool resume = std::find(args.begin(), args.end(), "--resume") != args.end();
      const std::string frames = resume ? "2" : "1";
      bool found = false;
      for (std::size_t i = 0; i + 1 < args.size(); ++i)
        if (args[i] == "--frames") {
          args[i + 1] = frames;
          found = true;
        }
      if (!found) args.insert(args.end(), {"--frames", frames});
      if (!resume && args.size() > 1 && has_substeps(work / args[1])) args.insert(args.end(), {"--set", "integrator.substeps=2"});
    } else if (cmd == "study" && args.size() >= 3) {
      // One measurement time and two step levels of the same combos.
      std::string study = slurp(work / args[2]);
      study = std::regex_replace(study, std::regex(R"(\ntimes: \[([^,\]]+)[^\]]*\])"), "\ntimes: [$1]");
      study = std::regex_replace(study, std::regex(R"(levels: \d+)"), "levels: 2");
      // and a coarser reference step (checked by halving all the same): 5e-5 s divides the
      // ladder's steps and the shipped studies' times.
      study = std::regex_replace(study, std::regex(R"((reference: \{integrator: rk4, dt: )[0-9.eE+-]+)"), "$015.0e-5");
      const fs::path copy = work / ("short_" + fs::path(args[2]).filename().string());
      std::ofstream(copy) << study;
      args[2] = copy.string();
    } else if (cmd == "plot") {
      if (std::system("/usr/bin/python3 -c 'import matplotlib' >/dev/null 2>&1") != 0)
        ex.skip = "python3-matplotlib is not installed";
    } else if (cmd == "render" || cmd == "view") {
      if (!fs::exists(fs::path(LOOM_EXE).parent_path().parent_path() / "lib/loom/plugins/loom_renderer_gl.so"))
        ex.skip = "this build has no gl renderer";
      if (cmd == "view") ex.skip = "loom view needs a display";
    }
    if (!prefix.empty()) {
      if (shell("command -v mpirun").code != 0) ex.skip = "mpirun is not installed";
      if (!fs::exists(fs::path(LOOM_EXE).parent_path().parent_path() / "lib/loom/plugins/loom_solver_petsc.so"))
        ex.skip = "this build has no petsc solver";
    }
    std::string c = "cd " + quote(work.string()) + " && " + env;
    for (const auto& p : prefix) c += p + " ";
    c += quote(LOOM_EXE);
    for (const auto& a : args) c += " " + quote(a);
    ex.command = c;
    out.push_back(ex);
  }
  return out;
}

}  // namespace

TEST(Readme, EveryExampleCommandRuns) {
  const fs::path work = fs::temp_directory_path() / "loom_readme_examples";
  fs::remove_all(work);
  fs::create_directories(work);
  for (const char* d : {"scenes", "studies", "materials", "data", "scripts"})
    fs::create_directory_symlink(kRoot / d, work / d);
  const auto list = examples(work);
  ASSERT_GE(list.size(), 8u) << "the README's examples were not found";
  int ran = 0;
  for (const Example& ex : list) {
    if (!ex.skip.empty()) {
      std::printf("skipped (%s): %s\n", ex.skip.c_str(), ex.readme_line.c_str());
      continue;
    }
    const auto t0 = std::chrono::steady_clock::now();
    const Result r = shell(ex.command);
    std::printf("%.1f s: %s\n", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
                ex.readme_line.c_str());
    EXPECT_EQ(r.code, 0) << "README: " << ex.readme_line << "\nran: " << ex.command << "\n" << r.out;
    ++ran;
  }
  EXPECT_GE(ran, 6);
  // What the examples promise is there.
  EXPECT_TRUE(fs::exists(work / "out/hanging_cloth/frame_00001.obj"));
  EXPECT_TRUE(fs::exists(work / "out/hanging_paraview/run.pvd"));
  EXPECT_TRUE(fs::exists(work / "out/hanging_paraview/frame_00002.vtu"));  // after --resume
}

TEST(Readme, SynopsisNamesOnlyCommandsAndFlagsTheProgramKnows) {
  const std::string help = shell(quote(LOOM_EXE) + " --help").out;
  const std::string readme = slurp(kRoot / "README.md");
  int checked = 0;
  for (const std::string& line : block_lines(readme, "")) {
    const auto w = words(line);
    if (w.size() < 2 || w[0] != "loom") continue;
    EXPECT_NE(help.find("loom " + w[1]), std::string::npos) << "README synopsis: " << line;
    for (const auto& t : w) {
      static const std::regex flag(R"(--[a-z-]+)");
      for (std::sregex_iterator m(t.begin(), t.end(), flag), e; m != e; ++m)
        EXPECT_NE(help.find(m->str()), std::string::npos) << m->str() << " in README synopsis: " << line;
    }
    ++checked;
  }
  EXPECT_GE(checked, 8);
  // Every command `loom --help` lists appears in the README synopsis.
  static const std::regex cmd(R"(\n  loom ([a-z]+))");
  for (std::sregex_iterator m(help.begin(), help.end(), cmd), e; m != e; ++m)
    EXPECT_NE(readme.find("loom " + (*m)[1].str()), std::string::npos) << (*m)[1] << " is not in the README";
}

TEST(Readme, InlineSetExampleValidates) {
  const std::string readme = slurp(kRoot / "README.md");
  static const std::regex span("`(--set [^`]+)`");
  int checked = 0;
  for (std::sregex_iterator m(readme.begin(), readme.end(), span), e; m != e; ++m) {
    std::string c = "cd " + quote(kRoot.string()) + " && " + quote(LOOM_EXE) + " validate scenes/hanging_cloth.yaml";
    for (const auto& w : words((*m)[1].str())) c += " " + quote(w);
    const Result r = shell(c);
    EXPECT_EQ(r.code, 0) << (*m)[1] << "\n" << r.out;
    ++checked;
  }
  EXPECT_GE(checked, 1);
}
