// ParamFields<Options>: a ParamSpec whose keys are bound to the members of an options struct,
// so that each key is declared once and that one line also reads it: the default is the member's
// value in a default-constructed Options, and read(p) fills an Options through a ParamReader
// (ranges, choices and error messages from the declaration, loom/param_spec.hpp).
//
//   const loom::ParamFields<MyOptions>& fields() {
//     static const loom::ParamFields<MyOptions> f = [] {
//       loom::ParamFields<MyOptions> f("my_solver", "what it is");
//       f.number("tolerance", &MyOptions::tolerance).range(loom::ParamRange::positive()).help("...");
//       f.choice("ordering", &MyOptions::ordering, {"amd", "metis"}).help("...");
//       return f;
//     }();
//     return f;
//   }
//   const loom::ParamSpec& MyOptions::spec() { return fields().spec(); }
//   MyOptions MyOptions::from_params(const loom::Params& p) { return fields().read(p); }
//
// The keys are read in the order they are declared (the first bad one is the one reported).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "loom/param_spec.hpp"

namespace loom {

template <class Options>
class ParamFields {
 public:
  explicit ParamFields(std::string name, std::string summary = "") : spec_(std::move(name), std::move(summary)) {}

  ParamDeclBuilder number(const std::string& key, double Options::*m) {
    bind(key, [m](const ParamReader& r, const std::string& k, Options& o) { o.*m = r.number(k); });
    return spec_.number(key, defaults_.*m);
  }
  ParamDeclBuilder integer(const std::string& key, int Options::*m) {
    bind(key, [m](const ParamReader& r, const std::string& k, Options& o) { o.*m = r.int32(k); });
    return spec_.integer(key, static_cast<std::int64_t>(defaults_.*m));
  }
  ParamDeclBuilder flag(const std::string& key, bool Options::*m) {
    bind(key, [m](const ParamReader& r, const std::string& k, Options& o) { o.*m = r.flag(k); });
    return spec_.flag(key, defaults_.*m);
  }
  ParamDeclBuilder text(const std::string& key, std::string Options::*m) {
    bind(key, [m](const ParamReader& r, const std::string& k, Options& o) { o.*m = r.text(k); });
    return spec_.text(key, defaults_.*m);
  }
  ParamDeclBuilder choice(const std::string& key, std::string Options::*m, std::vector<std::string> choices) {
    bind(key, [m](const ParamReader& r, const std::string& k, Options& o) { o.*m = r.text(k); });
    return spec_.choice(key, defaults_.*m, std::move(choices));
  }

  const ParamSpec& spec() const { return spec_; }

  /// An Options with every bound key read from p (defaults for the absent ones).
  Options read(const Params& p) const {
    Options o;
    read(p, o);
    return o;
  }
  /// Sets the bound members of o from p (defaults for the absent keys); other members stay.
  void read(const Params& p, Options& o) const {
    const ParamReader r(p, spec_);
    for (const auto& [key, f] : reads_) f(r, key, o);
  }

 private:
  using Read = std::function<void(const ParamReader&, const std::string&, Options&)>;
  void bind(const std::string& key, Read f) { reads_.emplace_back(key, std::move(f)); }

  Options defaults_{};
  ParamSpec spec_;
  std::vector<std::pair<std::string, Read>> reads_;
};

}  // namespace loom
