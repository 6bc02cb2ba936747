// Params: a typed, checked view of one YAML mapping (a plugin's parameters).
//
// Plugins read their parameters through Params; every read marks the key as used, and
// after the factory returns the framework calls check_unused(), which rejects unknown
// keys with a "did you mean" hint. Errors name the file and line of the offending value.
// yaml-cpp stays behind this interface (plugins need not include it).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "loom/common.hpp"

namespace loom {

class ParamSpec;

class Params {
 public:
  struct Impl;
  Params();
  explicit Params(std::shared_ptr<Impl> impl);
  ~Params();
  Params(const Params&);
  Params& operator=(const Params&);

  /// Parse a YAML document from text (used by tests and by Params::from_file).
  static Params from_string(const std::string& yaml, const std::string& source_name = "<string>");
  static Params from_file(const std::string& path);

  bool valid() const;        ///< false for a missing node
  bool is_map() const;
  bool is_sequence() const;
  bool is_scalar() const;
  bool has(const std::string& key) const;
  std::vector<std::string> keys() const;   ///< keys of a mapping, in file order
  std::size_t size() const;                ///< sequence length

  /// Where this node is: "file:line" (or just "file").
  std::string where() const;
  /// Dotted path of this node inside the document, e.g. "material.stiffness".
  std::string path() const;
  std::string source() const;

  /// Child node (marks the key as used). Missing keys give an invalid Params.
  Params child(const std::string& key) const;
  Params at(std::size_t i) const;

  // Typed scalar reads of this node; throw InputError naming file:line and the expected type.
  double as_double() const;
  std::int64_t as_int() const;
  bool as_bool() const;
  std::string as_string() const;
  std::vector<double> as_doubles() const;  ///< a sequence of numbers

  // Typed reads of a child with a default; throw InputError on a wrong type.
  double get(const std::string& key, double def) const;
  std::int64_t get(const std::string& key, std::int64_t def) const;
  int get(const std::string& key, int def) const;
  bool get(const std::string& key, bool def) const;
  std::string get(const std::string& key, const std::string& def) const;
  std::string get(const std::string& key, const char* def) const;

  // Required reads: throw InputError "missing key" when absent.
  double require_double(const std::string& key) const;
  std::int64_t require_int(const std::string& key) const;
  std::string require_string(const std::string& key) const;

  /// Range-checked reads (finite; lo/hi inclusive unless strict). Fix hint names the range.
  double get_positive(const std::string& key, double def) const;      ///< > 0 and finite
  double get_nonnegative(const std::string& key, double def) const;   ///< >= 0 and finite
  double get_in_range(const std::string& key, double def, double lo, double hi) const;
  std::string get_choice(const std::string& key, const std::string& def,
                         const std::vector<std::string>& choices) const;

  /// Mark a key as used without reading it (the framework reads it elsewhere).
  void mark_used(const std::string& key) const;
  /// Throw InputError for the first key of this mapping that was never read, with a
  /// "did you mean" suggestion among the keys that were read. A key whose value is null
  /// counts as absent (so --set integrator.kang_cho_damping=null removes a key).
  void check_unused(const std::vector<std::string>& also_known = {}) const;

  /// Throw InputError "<where>: <message>" for this node.
  [[noreturn]] void fail(const std::string& message) const;

  /// Set a value by dotted path (creating maps on the way); used for --set overrides.
  /// The value text is parsed as YAML (so "0.5", "[0,1,0]", "true" work).
  void set_path(const std::string& dotted_key, const std::string& value_yaml);

  /// Emit this node as YAML text (flow = on one line: [a, b], {k: v}).
  std::string dump(bool flow = false) const;

  /// This node with a declared spec attached (loom/param_spec.hpp): child() and mark_used()
  /// of an undeclared key then throw std::logic_error, children of a Map key carry its nested
  /// spec, and check_unused() suggests declared keys. The spec must outlive the returned view.
  Params with_spec(const ParamSpec* spec) const;
  const ParamSpec* spec() const;

  const std::shared_ptr<Impl>& impl() const { return impl_; }

 private:
  std::shared_ptr<Impl> impl_;
};

/// The closest candidate to `word` by edit distance, or "" if none is close.
std::string closest_match(const std::string& word, const std::vector<std::string>& candidates);

}  // namespace loom
