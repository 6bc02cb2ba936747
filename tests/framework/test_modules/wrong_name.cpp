// A module whose file name promises 'test_wrong_name' but which registers something else.
#include <loom/plugin.hpp>
namespace {
void reg(loom::Registry& r) {
  r.add_material({loom::PluginKind::Material, "something_else", "cpu", "1.0", ""},
                 [](const loom::Params&, const loom::Mesh&) -> std::unique_ptr<loom::Material> { return nullptr; });
}
}  // namespace
LOOM_PLUGIN(reg)
