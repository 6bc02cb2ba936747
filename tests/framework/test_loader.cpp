#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "common/input_error.hpp"
#include "loom/registry.hpp"

using loom_test::error_of;

TEST(Loader, LoadsOnlyTheNamedModule) {
  loom::Registry reg;
  loom::PluginLoader loader(reg, {LOOM_TEST_PLUGIN_DIR});
  EXPECT_FALSE(reg.has(loom::PluginKind::Material, "test_gravity_only"));
  loader.ensure(loom::PluginKind::Material, "test_gravity_only");
  EXPECT_TRUE(reg.has(loom::PluginKind::Material, "test_gravity_only"));
  // nothing else was loaded
  EXPECT_EQ(reg.list().size(), 1u);
  EXPECT_NE(reg.list()[0].module_path.find("loom_material_test_gravity_only.so"), std::string::npos);
  // idempotent
  loader.ensure(loom::PluginKind::Material, "test_gravity_only");
  EXPECT_EQ(reg.list().size(), 1u);
}

TEST(Loader, UnknownNameListsAvailableAndSuggests) {
  loom::Registry reg;
  loom::PluginLoader loader(reg, {LOOM_TEST_PLUGIN_DIR});
  const std::string e = error_of([&] { loader.ensure(loom::PluginKind::Material, "test_gravity_onyl"); });
  EXPECT_NE(e.find("unknown material 'test_gravity_onyl'"), std::string::npos) << e;
  EXPECT_NE(e.find("did you mean 'test_gravity_only'"), std::string::npos) << e;
  EXPECT_NE(e.find("LOOM_PLUGIN_PATH"), std::string::npos) << e;
}

TEST(Loader, RefusesWrongAbi) {
  loom::Registry reg;
  loom::PluginLoader loader(reg, {LOOM_TEST_PLUGIN_DIR});
  const std::string e = error_of([&] { loader.ensure(loom::PluginKind::Material, "test_bad_abi"); });
  EXPECT_NE(e.find("ABI version"), std::string::npos) << e;
  EXPECT_NE(e.find("rebuild"), std::string::npos) << e;
}

TEST(Loader, ModuleMustRegisterItsName) {
  loom::Registry reg;
  loom::PluginLoader loader(reg, {LOOM_TEST_PLUGIN_DIR});
  const std::string e = error_of([&] { loader.ensure(loom::PluginKind::Material, "test_wrong_name"); });
  EXPECT_NE(e.find("did not register material 'test_wrong_name'"), std::string::npos) << e;
}

TEST(Loader, CorruptModuleIsAClearError) {
  const std::string dir = std::string(LOOM_BINARY_DIR) + "/tests/framework/corrupt_plugins";
  std::filesystem::create_directories(dir);
  std::ofstream(dir + "/loom_material_corrupt.so") << "not an ELF file";
  loom::Registry reg;
  loom::PluginLoader loader(reg, {dir});
  const std::string e = error_of([&] { loader.ensure(loom::PluginKind::Material, "corrupt"); });
  EXPECT_NE(e.find("cannot load plugin module"), std::string::npos) << e;
}

TEST(Loader, NamesAndLoadAll) {
  loom::Registry reg;
  loom::PluginLoader loader(reg, {LOOM_TEST_PLUGIN_DIR});
  const auto mats = loader.names(loom::PluginKind::Material);
  EXPECT_NE(std::find(mats.begin(), mats.end(), "test_gravity_only"), mats.end());
  std::vector<std::string> errors;
  loader.load_all(errors);
  EXPECT_EQ(errors.size(), 1u);  // the bad-ABI module
  EXPECT_TRUE(reg.has(loom::PluginKind::Integrator, "test_explicit_euler"));
  EXPECT_TRUE(reg.has(loom::PluginKind::Solver, "test_identity"));
}

TEST(Loader, EnvironmentPathComesFirst) {
  setenv("LOOM_PLUGIN_PATH", "/tmp/loom_a:/tmp/loom_b", 1);
  const auto path = loom::PluginLoader::default_search_path();
  unsetenv("LOOM_PLUGIN_PATH");
  ASSERT_GE(path.size(), 3u);
  EXPECT_EQ(path[0], "/tmp/loom_a");
  EXPECT_EQ(path[1], "/tmp/loom_b");
}
