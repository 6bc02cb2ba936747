// ParamSpec: the declared parameters of one plugin (or one framework section), the single
// source of truth for parsing, validation, `loom plugins --params NAME` and the parameter
// tables in docs/plugins/*.md.
//
// A plugin declares every key once, next to the code that reads it, and reads the values
// through a ParamReader, which takes the default, the range and the choices from the
// declaration:
//
//   const loom::ParamSpec& my_spec() {
//     static const loom::ParamSpec s = [] {
//       loom::ParamSpec s("my_material");
//       const MyOptions d;   // the defaults live in the options struct
//       s.number("stiffness", d.stiffness).range(loom::ParamRange::positive()).units("N/m")
//           .help("spring constant");
//       s.choice("stencil", "mesh", {"mesh", "grid"}).help("which springs to build");
//       return s;
//     }();
//     return s;
//   }
//   MyOptions parse(const loom::Params& p) {
//     const loom::ParamReader r(p, my_spec());
//     MyOptions o;
//     o.stiffness = r.number("stiffness");   // default, range check and error text from the spec
//     ...
//   }
//
// The registry attaches the plugin's spec to the Params it hands to the factory, so a read of
// a key the spec does not declare throws std::logic_error (a bug in the plugin, found by
// tests/param_spec), and check_unused() suggests declared keys for a typo and names the
// backends that honour a key the chosen backend ignores.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "loom/params.hpp"

namespace loom {

enum class ParamType { Number, Int, Bool, String, Enum, Vec3, List, Map };
const char* to_string(ParamType t);

/// A closed, open or half-open interval; infinite ends are unbounded.
struct ParamRange {
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  bool min_open = false, max_open = false;

  static ParamRange positive() { return {0.0, std::numeric_limits<double>::infinity(), true, false}; }
  static ParamRange nonnegative() { return {0.0, std::numeric_limits<double>::infinity(), false, false}; }
  static ParamRange closed(double lo, double hi) { return {lo, hi, false, false}; }
  static ParamRange at_least(double lo) { return {lo, std::numeric_limits<double>::infinity(), false, false}; }

  bool bounded() const;                 ///< either end finite
  bool contains(double v) const;        ///< also false for NaN and infinities
  std::string text() const;             ///< "> 0", ">= 0", "[1, 20]", "(0, 1]"; "" when unbounded
};

class ParamSpec;

struct ParamDecl {
  std::string name;
  ParamType type = ParamType::Number;
  bool required = false;
  bool has_default = false;            ///< a value is used when the key is absent
  std::string default_text;            ///< as shown to users ("1e-08", "true", "[0, -9.81, 0]", "from the material file")
  bool default_is_value = true;        ///< default_text is a value (shown as code), not a description
  double default_number = 0;           ///< Number, Int
  bool default_bool = false;
  std::string default_string;          ///< String, Enum
  std::vector<double> default_vec;     ///< Vec3
  ParamRange range;                    ///< Number, Int (and the Number form of a number-or-map key)
  std::vector<std::string> choices;    ///< Enum
  std::string units;
  std::string help;                    ///< one line
  std::vector<std::string> backends;   ///< backends that honour the key; empty: every backend
  std::shared_ptr<const ParamSpec> fields;  ///< Map: its keys
  bool number_or_map = false;          ///< Map that may also be given as one number
  bool framework = false;              ///< read by the framework (scene builder), not the plugin
  std::string shown_type;              ///< type column when it is not one type ("string | map")

  std::string type_text() const;       ///< "number", "int", "enum", "number | map", ...
  std::string range_text() const;      ///< range, or the enum's choices
  bool honoured_by(const std::string& backend) const;
};

/// Chainable setters for the declaration just added.
class ParamDeclBuilder {
 public:
  ParamDeclBuilder(ParamSpec& spec, std::size_t index) : spec_(&spec), index_(index) {}
  ParamDeclBuilder& range(const ParamRange& r);
  ParamDeclBuilder& units(const std::string& u);
  ParamDeclBuilder& help(const std::string& h);
  ParamDeclBuilder& backends(std::vector<std::string> b);
  /// Shown in the default column when the value used in the key's absence is not a constant.
  ParamDeclBuilder& default_text(const std::string& t);
  ParamDeclBuilder& no_default(const std::string& shown = "none");
  ParamDeclBuilder& required();
  ParamDeclBuilder& framework();
  ParamDeclBuilder& shown_type(const std::string& t);
  ParamDecl& decl();

 private:
  ParamSpec* spec_;
  std::size_t index_;
};

class ParamSpec {
 public:
  ParamSpec() = default;
  explicit ParamSpec(std::string name, std::string summary = "") : name_(std::move(name)), summary_(std::move(summary)) {}

  const std::string& name() const { return name_; }
  const std::string& summary() const { return summary_; }

  ParamDeclBuilder number(const std::string& key, double def);
  ParamDeclBuilder integer(const std::string& key, std::int64_t def);
  ParamDeclBuilder flag(const std::string& key, bool def);
  ParamDeclBuilder text(const std::string& key, const std::string& def);
  ParamDeclBuilder choice(const std::string& key, const std::string& def, std::vector<std::string> choices);
  ParamDeclBuilder vec3(const std::string& key, std::array<double, 3> def);
  ParamDeclBuilder list(const std::string& key);
  /// A nested mapping with its own keys.
  ParamDeclBuilder map(const std::string& key, ParamSpec fields);
  /// A nested mapping whose keys the code that reads it checks (not declared here).
  ParamDeclBuilder open_map(const std::string& key);
  /// A number, or a mapping of `fields` (e.g. stiffness: 500 or stiffness: {structural: 500, bend: 10}).
  ParamDeclBuilder number_or_map(const std::string& key, double def, ParamSpec fields);
  /// Append every declaration of `other` (e.g. the framework's keys before a plugin's).
  ParamSpec& append(const ParamSpec& other);

  const std::vector<ParamDecl>& decls() const { return decls_; }
  std::vector<ParamDecl>& decls() { return decls_; }
  const ParamDecl* find(const std::string& key) const;
  /// Declared keys (all backends).
  std::vector<std::string> keys() const;

  /// A table a user can read: key, type, default, range, units, backends, help (nested
  /// keys as parent.key). `markdown` gives a GitHub table for docs/plugins/*.md.
  std::string table(bool markdown = false) const;

 private:
  ParamDeclBuilder add(ParamDecl d);
  std::string name_, summary_;
  std::vector<ParamDecl> decls_;
};

/// Reads values of a Params mapping through a spec: defaults, ranges and choices come from the
/// declaration; errors go through Params::fail (InputError with file:line). Reading a key the
/// spec does not declare, or with the wrong type, throws std::logic_error (a plugin bug).
class ParamReader {
 public:
  /// Attaches `spec` to (a view of) p unless p already carries one (the registry's, which
  /// contains `spec`).
  ParamReader(const Params& p, const ParamSpec& spec);

  bool has(const std::string& key) const;      ///< present and not null
  double number(const std::string& key) const;
  std::int64_t integer(const std::string& key) const;
  int int32(const std::string& key) const;     ///< integer() that fits an int (the range should say so)
  bool flag(const std::string& key) const;
  std::string text(const std::string& key) const;   ///< String or Enum (choices checked)
  std::array<double, 3> vec3(const std::string& key) const;
  /// A Map or List key's node, with the nested spec attached (an invalid Params when absent).
  Params node(const std::string& key) const;
  /// A reader of a Map key's node through its nested spec.
  ParamReader section(const std::string& key) const;
  const Params& params() const { return p_; }
  const ParamSpec& spec() const { return *spec_; }

 private:
  const ParamDecl& decl(const std::string& key, std::initializer_list<ParamType> types) const;
  void check_range(const ParamDecl& d, const Params& c, double v) const;
  Params p_;
  const ParamSpec* spec_;
};

/// Reads every key that `p` gives through `spec`, as a plugin's factory would: types, ranges,
/// choices, required keys (not the framework's: `type`), the keys of nested maps that declare theirs, then rejects keys the spec
/// does not declare (with the "did you mean" of check_unused). Errors go through Params::fail
/// (InputError with file:line and the fix). For a block that the run does not read itself, such
/// as a fallback solver's in `solver: {type: [cholmod, filtered_pcg], filtered_pcg: {...}}`, so
/// that a typo there is reported where it is written, not on the machine that falls back to it.
void check_params(const Params& p, const ParamSpec& spec);

/// The declared keys of the framework's own sections of a scene (scene builder, renderer
/// command), merged before a plugin's keys in `loom plugins --params` and in the registry.
const ParamSpec& material_section_spec();
const ParamSpec& integrator_section_spec();
const ParamSpec& render_section_spec();

/// Keys honoured only by execution backends that run integrators on a device (precision,
/// host_sync_every), read by those backends through this spec; the CPU integrators append
/// them (declare_device_keys) so that one spec serves the cpu and cuda variants of a plugin.
const ParamSpec& device_keys_spec();
void declare_device_keys(ParamSpec& s);

}  // namespace loom
