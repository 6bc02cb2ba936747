#include "loom/param_spec.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace loom {

namespace {

std::string num_text(double v) {
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  std::ostringstream os;
  os.precision(10);
  os << v;
  return os.str();
}

std::string join(const std::vector<std::string>& v, const char* sep) {
  std::string out;
  for (const auto& s : v) out += (out.empty() ? "" : sep) + s;
  return out;
}

/// The declaration of `key`, of type `type`, with a default shown to users as `text`.
ParamDecl with_default(const std::string& key, ParamType type, std::string text) {
  ParamDecl d;
  d.name = key;
  d.type = type;
  d.has_default = true;
  d.default_text = std::move(text);
  return d;
}

/// The declaration of `key`, of type `type`, without a default ("none" in the tables).
ParamDecl without_default(const std::string& key, ParamType type) {
  ParamDecl d;
  d.name = key;
  d.type = type;
  d.default_text = "none";
  d.default_is_value = false;
  return d;
}

}  // namespace

const char* to_string(ParamType t) {
  switch (t) {
    case ParamType::Number: return "number";
    case ParamType::Int: return "int";
    case ParamType::Bool: return "bool";
    case ParamType::String: return "string";
    case ParamType::Enum: return "enum";
    case ParamType::Vec3: return "vec3";
    case ParamType::List: return "list";
    case ParamType::Map: return "map";
  }
  return "?";
}

// ---- ParamRange ----

bool ParamRange::bounded() const { return std::isfinite(min) || std::isfinite(max); }

bool ParamRange::contains(double v) const {
  if (!std::isfinite(v)) return false;
  if (min_open ? !(v > min) : !(v >= min)) return false;
  if (max_open ? !(v < max) : !(v <= max)) return false;
  return true;
}

std::string ParamRange::text() const {
  const bool lo = std::isfinite(min), hi = std::isfinite(max);
  if (lo && hi) return std::string(min_open ? "(" : "[") + num_text(min) + ", " + num_text(max) + (max_open ? ")" : "]");
  if (lo) return std::string(min_open ? "> " : ">= ") + num_text(min);
  if (hi) return std::string(max_open ? "< " : "<= ") + num_text(max);
  return "";
}

// ---- ParamDecl ----

std::string ParamDecl::type_text() const {
  if (!shown_type.empty()) return shown_type;
  if (number_or_map) return "number | map";
  return to_string(type);
}

std::string ParamDecl::range_text() const {
  if (type == ParamType::Enum) return join(choices, " | ");
  if (type == ParamType::Number || type == ParamType::Int || number_or_map) return range.text();
  return "";
}

bool ParamDecl::honoured_by(const std::string& backend) const {
  return backends.empty() || std::find(backends.begin(), backends.end(), backend) != backends.end();
}

// ---- builder ----

ParamDecl& ParamDeclBuilder::decl() { return spec_->decls()[index_]; }
ParamDeclBuilder& ParamDeclBuilder::range(const ParamRange& r) {
  decl().range = r;
  return *this;
}
ParamDeclBuilder& ParamDeclBuilder::units(const std::string& u) {
  decl().units = u;
  return *this;
}
ParamDeclBuilder& ParamDeclBuilder::help(const std::string& h) {
  decl().help = h;
  return *this;
}
ParamDeclBuilder& ParamDeclBuilder::backends(std::vector<std::string> b) {
  decl().backends = std::move(b);
  return *this;
}
ParamDeclBuilder& ParamDeclBuilder::default_text(const std::string& t) {
  decl().default_text = t;
  decl().default_is_value = false;
  return *this;
}
ParamDeclBuilder& ParamDeclBuilder::no_default(const std::string& shown) {
  decl().has_default = false;
  decl().default_text = shown;
  decl().default_is_value = false;
  return *this;
}
ParamDeclBuilder& ParamDeclBuilder::required() {
  decl().required = true;
  decl().has_default = false;
  decl().default_text = "required";
  decl().default_is_value = false;
  return *this;
}
ParamDeclBuilder& ParamDeclBuilder::shown_type(const std::string& t) {
  decl().shown_type = t;
  return *this;
}
ParamDeclBuilder& ParamDeclBuilder::framework() {
  decl().framework = true;
  return *this;
}

// ---- ParamSpec ----

ParamDeclBuilder ParamSpec::add(ParamDecl d) {
  if (find(d.name)) throw std::logic_error("parameter spec '" + name_ + "' declares '" + d.name + "' twice");
  decls_.push_back(std::move(d));
  return ParamDeclBuilder(*this, decls_.size() - 1);
}

ParamDeclBuilder ParamSpec::number(const std::string& key, double def) {
  ParamDecl d = with_default(key, ParamType::Number, num_text(def));
  d.default_number = def;
  return add(std::move(d));
}

ParamDeclBuilder ParamSpec::integer(const std::string& key, std::int64_t def) {
  ParamDecl d = with_default(key, ParamType::Int, std::to_string(def));
  d.default_number = static_cast<double>(def);
  return add(std::move(d));
}

ParamDeclBuilder ParamSpec::flag(const std::string& key, bool def) {
  ParamDecl d = with_default(key, ParamType::Bool, def ? "true" : "false");
  d.default_bool = def;
  return add(std::move(d));
}

ParamDeclBuilder ParamSpec::text(const std::string& key, const std::string& def) {
  ParamDecl d = with_default(key, ParamType::String, def.empty() ? "\"\"" : def);
  d.default_string = def;
  return add(std::move(d));
}

ParamDeclBuilder ParamSpec::choice(const std::string& key, const std::string& def, std::vector<std::string> choices) {
  if (std::find(choices.begin(), choices.end(), def) == choices.end())
    throw std::logic_error("parameter spec '" + name_ + "': the default '" + def + "' of '" + key + "' is not a choice");
  ParamDecl d = with_default(key, ParamType::Enum, def);
  d.default_string = def;
  d.choices = std::move(choices);
  return add(std::move(d));
}

ParamDeclBuilder ParamSpec::vec3(const std::string& key, std::array<double, 3> def) {
  ParamDecl d =
      with_default(key, ParamType::Vec3, "[" + num_text(def[0]) + ", " + num_text(def[1]) + ", " + num_text(def[2]) + "]");
  d.default_vec.assign(def.begin(), def.end());
  return add(std::move(d));
}

ParamDeclBuilder ParamSpec::list(const std::string& key) { return add(without_default(key, ParamType::List)); }

ParamDeclBuilder ParamSpec::map(const std::string& key, ParamSpec fields) {
  ParamDecl d = without_default(key, ParamType::Map);
  d.fields = std::make_shared<const ParamSpec>(std::move(fields));
  return add(std::move(d));
}

ParamDeclBuilder ParamSpec::open_map(const std::string& key) { return add(without_default(key, ParamType::Map)); }

ParamDeclBuilder ParamSpec::number_or_map(const std::string& key, double def, ParamSpec fields) {
  ParamDecl d = with_default(key, ParamType::Map, num_text(def));
  d.number_or_map = true;
  d.default_number = def;
  d.fields = std::make_shared<const ParamSpec>(std::move(fields));
  return add(std::move(d));
}

ParamSpec& ParamSpec::append(const ParamSpec& other) {
  for (const auto& d : other.decls_) add(d);
  return *this;
}

const ParamDecl* ParamSpec::find(const std::string& key) const {
  for (const auto& d : decls_)
    if (d.name == key) return &d;
  return nullptr;
}

std::vector<std::string> ParamSpec::keys() const {
  std::vector<std::string> out;
  for (const auto& d : decls_) out.push_back(d.name);
  return out;
}

namespace {

struct Row {
  std::string key, type, def, range, units, backends, help;
  bool def_is_value = true;
};

void collect_rows(const ParamSpec& s, const std::string& prefix, std::vector<Row>& rows) {
  for (const auto& d : s.decls()) {
    Row r{prefix + d.name, d.type_text(), d.default_text, d.range_text(), d.units,
          d.framework ? "framework" : (d.backends.empty() ? "all" : join(d.backends, ", ")), d.help,
          d.default_is_value};
    rows.push_back(r);
    if (d.fields) collect_rows(*d.fields, prefix + d.name + ".", rows);
  }
}

}  // namespace

std::string ParamSpec::table(bool markdown) const {
  std::vector<Row> rows;
  collect_rows(*this, "", rows);
  const Row head{"key", "type", "default", "range", "units", "backends", "help"};
  std::ostringstream os;
  if (markdown) {
    // A '|' inside a cell would end it: escape it (GitHub tables, code spans included).
    auto cell = [](const std::string& s) {
      std::string out;
      for (char ch : s) out += ch == '|' ? std::string("\\|") : std::string(1, ch);
      return out;
    };
    auto code = [&](const std::string& s) { return s.empty() ? std::string("") : "`" + cell(s) + "`"; };
    os << "| " << head.key << " | " << head.type << " | " << head.def << " | " << head.range << " | " << head.units
       << " | " << head.backends << " | " << head.help << " |\n";
    os << "|---|---|---|---|---|---|---|\n";
    for (const auto& r : rows)
      os << "| " << code(r.key) << " | " << cell(r.type) << " | " << (r.def_is_value ? code(r.def) : cell(r.def)) << " | " << cell(r.range) << " | "
         << cell(r.units) << " | " << r.backends << " | " << cell(r.help) << " |\n";
    return os.str();
  }
  // Plain text: aligned columns.
  std::size_t w[6] = {head.key.size(), head.type.size(), head.def.size(), head.range.size(), head.units.size(),
                      head.backends.size()};
  for (const auto& r : rows) {
    w[0] = std::max(w[0], r.key.size());
    w[1] = std::max(w[1], r.type.size());
    w[2] = std::max(w[2], r.def.size());
    w[3] = std::max(w[3], r.range.size());
    w[4] = std::max(w[4], r.units.size());
    w[5] = std::max(w[5], r.backends.size());
  }
  auto line = [&](const Row& r) {
    auto pad = [](const std::string& s, std::size_t n) { return s + std::string(n > s.size() ? n - s.size() : 0, ' '); };
    os << pad(r.key, w[0]) << "  " << pad(r.type, w[1]) << "  " << pad(r.def, w[2]) << "  " << pad(r.range, w[3])
       << "  " << pad(r.units, w[4]) << "  " << pad(r.backends, w[5]) << "  " << r.help << "\n";
  };
  line(head);
  for (const auto& r : rows) line(r);
  return os.str();
}

// ---- ParamReader ----

// A Params that already carries a spec (the registry's: the section's keys and the plugin's)
// keeps it, so that the framework's keys stay declared in the reader's view.
ParamReader::ParamReader(const Params& p, const ParamSpec& spec) : p_(p.spec() ? p : p.with_spec(&spec)), spec_(&spec) {}

const ParamDecl& ParamReader::decl(const std::string& key, std::initializer_list<ParamType> types) const {
  const ParamDecl* d = spec_->find(key);
  if (!d)
    throw std::logic_error("'" + spec_->name() + "' reads the key '" + key +
                           "', which its parameter spec does not declare. Fix (in the code): declare it.");
  if (std::find(types.begin(), types.end(), d->type) == types.end())
    throw std::logic_error("'" + spec_->name() + "' reads the key '" + key + "' as another type than the " +
                           d->type_text() + " its spec declares.");
  return *d;
}

bool ParamReader::has(const std::string& key) const {
  decl(key, {ParamType::Number, ParamType::Int, ParamType::Bool, ParamType::String, ParamType::Enum, ParamType::Vec3,
             ParamType::List, ParamType::Map});
  return p_.has(key) && p_.child(key).valid();
}

void ParamReader::check_range(const ParamDecl& d, const Params& c, double v) const {
  if (d.range.contains(v)) return;
  const ParamRange& r = d.range;
  if (!r.bounded()) c.fail("must be a finite number (got " + num_text(v) + ").");
  const bool int_type = d.type == ParamType::Int;
  if (!int_type && r.min == 0 && !std::isfinite(r.max) && r.min_open)
    c.fail("must be a finite number > 0 (got " + num_text(v) + "). Fix: give a positive value.");
  if (!int_type && r.min == 0 && !std::isfinite(r.max) && !r.min_open)
    c.fail("must be a finite number >= 0 (got " + num_text(v) + "). Fix: give a value >= 0.");
  const bool both = std::isfinite(r.min) && std::isfinite(r.max);
  // Numbers in a closed range keep Params::get_in_range's wording.
  c.fail(std::string("must be ") + (int_type ? "an integer " : both ? "" : "a finite number ") +
         (both ? "in " + r.text() : r.text()) + " (got " + num_text(v) + ").");
}

double ParamReader::number(const std::string& key) const {
  const ParamDecl& d = decl(key, {ParamType::Number, ParamType::Map});
  const Params c = p_.child(key);
  if (!c.valid()) {
    if (d.required) p_.fail("missing required key '" + key + "' (a number).");
    if (!d.has_default) throw std::logic_error("'" + spec_->name() + "' reads '" + key + "' without a default: check has() first");
    return d.default_number;
  }
  if (d.type == ParamType::Map && !d.number_or_map) throw std::logic_error("'" + key + "' is a map, not a number");
  const double v = c.as_double();
  check_range(d, c, v);
  return v;
}

std::int64_t ParamReader::integer(const std::string& key) const {
  const ParamDecl& d = decl(key, {ParamType::Int});
  const Params c = p_.child(key);
  if (!c.valid()) {
    if (d.required) p_.fail("missing required key '" + key + "' (an integer).");
    if (!d.has_default) throw std::logic_error("'" + spec_->name() + "' reads '" + key + "' without a default: check has() first");
    return static_cast<std::int64_t>(d.default_number);
  }
  const std::int64_t v = c.as_int();
  check_range(d, c, static_cast<double>(v));
  return v;
}

int ParamReader::int32(const std::string& key) const {
  const std::int64_t v = integer(key);
  if (v < -2147483647LL || v > 2147483647LL) p_.child(key).fail("integer out of range.");
  return static_cast<int>(v);
}

bool ParamReader::flag(const std::string& key) const {
  const ParamDecl& d = decl(key, {ParamType::Bool});
  const Params c = p_.child(key);
  if (!c.valid()) {
    if (d.required) p_.fail("missing required key '" + key + "' (true or false).");
    return d.default_bool;
  }
  return c.as_bool();
}

std::string ParamReader::text(const std::string& key) const {
  const ParamDecl& d = decl(key, {ParamType::String, ParamType::Enum});
  if (d.required && !(p_.has(key) && p_.child(key).valid())) p_.fail("missing required key '" + key + "'.");
  if (d.type == ParamType::Enum) return p_.get_choice(key, d.default_string, d.choices);
  const Params c = p_.child(key);
  if (!c.valid()) {
    if (!d.has_default) throw std::logic_error("'" + spec_->name() + "' reads '" + key + "' without a default: check has() first");
    return d.default_string;
  }
  return c.as_string();
}

std::array<double, 3> ParamReader::vec3(const std::string& key) const {
  const ParamDecl& d = decl(key, {ParamType::Vec3});
  const Params c = p_.child(key);
  if (!c.valid()) {
    if (d.required) p_.fail("missing required key '" + key + "' (a vector [x, y, z]).");
    if (d.default_vec.size() != 3) throw std::logic_error("'" + spec_->name() + "' reads '" + key + "' without a default");
    return {d.default_vec[0], d.default_vec[1], d.default_vec[2]};
  }
  const std::vector<double> v = c.as_doubles();
  if (v.size() != 3) c.fail("expected a vector of 3 numbers like [0, 1, 0], got " + std::to_string(v.size()) + " numbers.");
  for (double x : v)
    if (!std::isfinite(x)) c.fail("the vector's components must be finite numbers.");
  return {v[0], v[1], v[2]};
}

Params ParamReader::node(const std::string& key) const {
  const ParamDecl& d = decl(key, {ParamType::Map, ParamType::List});
  if (d.required && !(p_.has(key) && p_.child(key).valid())) p_.fail("missing required key '" + key + "'.");
  return p_.child(key);  // child() attaches the nested spec of a Map
}

ParamReader ParamReader::section(const std::string& key) const {
  const ParamDecl& d = decl(key, {ParamType::Map});
  if (!d.fields) throw std::logic_error("'" + spec_->name() + "': '" + key + "' declares no keys to read through");
  return ParamReader(node(key), *d.fields);
}

void check_params(const Params& p, const ParamSpec& spec) {
  if (!p.valid()) return;
  if (!p.is_map()) p.fail("expected a mapping of '" + spec.name() + "' keys, like {key: value}.");
  const ParamReader r(p, spec);
  for (const ParamDecl& d : spec.decls()) {
    // An absent key is read only when it is required (the read reports it); a section's own
    // required keys (type) are the framework's business.
    if (!r.has(d.name) && !(d.required && !d.framework)) continue;
    switch (d.type) {
      case ParamType::Number: r.number(d.name); break;
      case ParamType::Int: r.integer(d.name); break;
      case ParamType::Bool: r.flag(d.name); break;
      case ParamType::String:
      case ParamType::Enum: r.text(d.name); break;
      case ParamType::Vec3: r.vec3(d.name); break;
      case ParamType::List: r.node(d.name); break;
      case ParamType::Map: {
        const Params c = r.node(d.name);
        if (d.number_or_map && c.is_scalar()) r.number(d.name);
        else if (d.fields) check_params(c, *d.fields);
        // an open map (no declared keys) is checked by the code that reads it
        break;
      }
    }
  }
  r.params().check_unused();
}

// ---- the framework's own sections ----

const ParamSpec& material_section_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("material section", "keys of the scene's material: section read by the scene builder");
    s.text("type", "").required().framework().help("material plugin name (loom plugins lists them)");
    s.text("fabric", "").no_default().framework().help(
        "measured fabric from the library (loom/fabric_library.hpp): fills in the material's curves and bending");
    s.open_map("bending").framework().help("hinge bending: a mapping whose keys docs/plugins/bending.md lists");
    return s;
  }();
  return s;
}

const ParamSpec& integrator_section_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("integrator section", "keys of the scene's integrator: section read by the scene builder");
    s.text("type", "").required().framework().help("integrator plugin name (loom plugins lists them)");
    s.number("dt", 1e-3).range(ParamRange::positive()).units("s").framework().help("time step");
    s.integer("substeps", 1).range(ParamRange::closed(1, 1e8)).framework().help("steps per output frame");
    s.number("frame_time", 1.0 / 60.0).range(ParamRange::positive()).units("s").framework().no_default("none").help(
        "time between output frames; sets substeps = frame_time / dt (give it or substeps, not both)");
    return s;
  }();
  return s;
}

const ParamSpec& render_section_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("render section", "keys of the scene's render: section read by the render command");
    s.text("type", "gl").framework().help("renderer plugin name");
    s.choice("video", "auto", {"auto", "on", "off"}).framework().help(
        "encode the frames as render.mp4 with ffmpeg (auto: when ffmpeg is on the PATH)");
    s.number("fps", 30).range(ParamRange::positive()).units("1/s").framework().help("frame rate of the video");
    s.choice("fit", "sequence", {"sequence", "first_frame"}).framework().help(
        "camera framing: the bounds of the whole sequence, or of the first frame");
    s.flag("ground", true).framework().help("draw the ground (a plane collider is the scene's own)");
    return s;
  }();
  return s;
}

const ParamSpec& device_keys_spec() {
  static const ParamSpec s = [] {
    ParamSpec s("device execution");
    s.choice("precision", "double", {"double", "float"}).backends({"cuda"}).help(
      "device arrays in double or float (coefficients are computed in double and rounded once)");
  s.integer("host_sync_every", 0).range(ParamRange::closed(0, 1000000)).units("steps").backends({"cuda"}).help(
      "0: copy x and v back to the host only when the framework reads them (guards on the device, stats and "
      "output once a frame); n: also after every n-th step (1 = every step)");
    return s;
  }();
  return s;
}

void declare_device_keys(ParamSpec& s) { s.append(device_keys_spec()); }

}  // namespace loom
