// The one MPI-rank rule (loom/launcher.hpp), shared by the output writer and the PETSc plugin.
// Each launcher's variable alone gives the rank; Open MPI's wins over the generic ones; a value
// that is not a non-negative integer is ignored. Under MVAPICH (MV2_COMM_WORLD_RANK only) rank 1
// must not write output, which the old output rule got wrong.
#include <gtest/gtest.h>

#include <cstdlib>

#include "loom/launcher.hpp"

namespace {

const char* const kVars[] = {"OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK", "MV2_COMM_WORLD_RANK", "SLURM_PROCID"};

struct CleanEnv : ::testing::Test {
  void SetUp() override {
    for (const char* v : kVars) unsetenv(v);
  }
  void TearDown() override { SetUp(); }
};

}  // namespace

TEST_F(CleanEnv, NoLauncherIsRankZero) {
  EXPECT_EQ(loom::launcher_rank(), 0);
  EXPECT_TRUE(loom::is_output_rank());
}

TEST_F(CleanEnv, EachLauncherVariableAloneGivesTheRank) {
  int r = 1;
  for (const char* v : kVars) {
    SetUp();
    setenv(v, std::to_string(r).c_str(), 1);
    EXPECT_EQ(loom::launcher_rank(), r) << v;
    EXPECT_FALSE(loom::is_output_rank()) << v;
    setenv(v, "0", 1);
    EXPECT_TRUE(loom::is_output_rank()) << v;
    ++r;
  }
}

TEST_F(CleanEnv, OpenMpiComesFirstAndGarbageIsIgnored) {
  setenv("SLURM_PROCID", "5", 1);
  setenv("PMI_RANK", "3", 1);
  EXPECT_EQ(loom::launcher_rank(), 3);
  setenv("OMPI_COMM_WORLD_RANK", "2", 1);
  EXPECT_EQ(loom::launcher_rank(), 2);
  setenv("OMPI_COMM_WORLD_RANK", "two", 1);   // not a number: the next variable decides
  EXPECT_EQ(loom::launcher_rank(), 3);
  setenv("PMI_RANK", "-1", 1);
  EXPECT_EQ(loom::launcher_rank(), 5);
  setenv("SLURM_PROCID", "", 1);
  EXPECT_EQ(loom::launcher_rank(), 0);
}
