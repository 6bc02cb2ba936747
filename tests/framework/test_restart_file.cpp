// restart.bin against its documented layout (docs/OUTPUT.md): the library writes exactly the
// bytes of an encoder written from the docs (tests/common/restart_file.hpp, standard 64-bit
// FNV-1a), reads them back, still reads the restart points of earlier builds (hash started from
// the mistyped basis 1469598103934665603), and calls any other hash damaged.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/input_error.hpp"
#include "common/restart_file.hpp"
#include "loom/restart.hpp"

namespace fs = std::filesystem;

namespace {

loom::RestartData sample() {
  loom::RestartData r;
  r.frame = 3;
  r.frames = 7;
  r.step = 120;
  r.time = 0.05;
  r.force_evaluations = 480;
  r.linear_iterations = 12345;
  r.x = {0.0, 1.0, -2.5, 0.125, 1e-300, 3.0};
  r.v = {-0.5, 0.25, 9.75, 0.0, -0.0, 1e10};
  r.integrator_state = {1.0, 2.0, 3.5};
  return r;
}

void expect_same(const loom::RestartData& a, const loom::RestartData& b) {
  EXPECT_EQ(a.frame, b.frame);
  EXPECT_EQ(a.frames, b.frames);
  EXPECT_EQ(a.step, b.step);
  EXPECT_EQ(a.time, b.time);
  EXPECT_EQ(a.force_evaluations, b.force_evaluations);
  EXPECT_EQ(a.linear_iterations, b.linear_iterations);
  EXPECT_EQ(a.x, b.x);
  EXPECT_EQ(a.v, b.v);
  EXPECT_EQ(a.integrator_state, b.integrator_state);
}

}  // namespace

TEST(RestartFile, BytesAreTheDocumentedLayoutWithTheStandardFnv1aHash) {
  // The standard FNV-1a 64 of "a" (published test vector: 0xaf63dc4c8601ec8c) checks the encoder's hash.
  std::uint64_t h = loom_test::kFnv1aBasis;
  h = (h ^ static_cast<unsigned char>('a')) * 1099511628211ULL;
  EXPECT_EQ(h, 0xaf63dc4c8601ec8cULL);
  EXPECT_EQ(loom::restart_bytes(sample()), loom_test::restart_file_bytes(sample()));
}

TEST(RestartFile, ReadsTheStandardAndTheEarlierHashAndRefusesAnyOther) {
  const fs::path dir = fs::temp_directory_path() / "loom_restart_file";
  fs::remove_all(dir);
  fs::create_directories(dir);
  auto write = [&](const std::string& bytes) { std::ofstream(dir / "restart.bin", std::ios::binary) << bytes; };
  write(loom_test::restart_file_bytes(sample()));
  expect_same(loom::read_restart(dir.string()), sample());
  write(loom_test::restart_file_bytes(sample(), 1469598103934665603ULL));  // before 2026-11-29
  expect_same(loom::read_restart(dir.string()), sample());
  std::string other = loom_test::restart_file_bytes(sample(), 1469598103934665604ULL);
  write(other);
  EXPECT_NE(loom_test::error_of([&] { loom::read_restart(dir.string()); }).find("checksum mismatch"), std::string::npos);
  std::string flipped = loom_test::restart_file_bytes(sample());
  flipped[60] ^= 1;  // inside x (which starts at byte 56)
  write(flipped);
  const std::string e = loom_test::error_of([&] { loom::read_restart(dir.string()); });
  EXPECT_NE(e.find("restart.bin: damaged restart point (checksum mismatch)"), std::string::npos) << e;
  fs::remove_all(dir);
}
