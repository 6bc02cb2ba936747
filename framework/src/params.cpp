#include "loom/params.hpp"

#include "loom/param_spec.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <system_error>
#include <fstream>
#include <map>
#include <utility>
#include <vector>
#include <set>
#include <sstream>
#include <stdexcept>

namespace loom {

namespace {
struct Doc {
  YAML::Node root;
  std::string source;
  std::map<std::string, std::set<std::string>> asked;  // path -> keys asked for
  /// Values set by set_path (`--set`), in order: the dotted path and "key=value" as given. A
  /// node at or below such a path came from the command line, not from a line of the file.
  std::vector<std::pair<std::string, std::string>> overrides;
};

/// The `--set key=value` that put the node at `path` there (the latest one that covers it), or
/// nullptr when the node comes from the file.
const std::string* override_for(const Doc& doc, const std::string& path) {
  for (auto it = doc.overrides.rbegin(); it != doc.overrides.rend(); ++it) {
    const std::string& k = it->first;
    if (path.size() >= k.size() && path.compare(0, k.size(), k) == 0 &&
        (path.size() == k.size() || path[k.size()] == '.' || path[k.size()] == '['))
      return &it->second;
  }
  return nullptr;
}
}  // namespace

struct Params::Impl {
  std::shared_ptr<Doc> doc;
  YAML::Node node;
  std::string path;   // dotted path, "" for the root
  bool present = true;
  int line = -1;      // 1-based line of this node (or of its parent when missing)
  const ParamSpec* spec = nullptr;  // declared keys of this mapping (with_spec), or none
};

namespace {

std::string join_path(const std::string& a, const std::string& b) { return a.empty() ? b : a + "." + b; }

int line_of(const YAML::Node& n, int fallback) {
  if (!n.IsDefined() || n.IsNull()) {
    // Null nodes still carry a mark when they come from the file.
    if (n.IsDefined() && n.Mark().line >= 0) return n.Mark().line + 1;
    return fallback;
  }
  return n.Mark().line >= 0 ? n.Mark().line + 1 : fallback;
}

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t sub = prev[j - 1] + (std::tolower(a[i - 1]) == std::tolower(b[j - 1]) ? 0 : 1);
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, sub});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string describe_value(const YAML::Node& n) {
  if (!n.IsDefined()) return "nothing";
  if (n.IsNull()) return "an empty value";
  if (n.IsScalar()) return "'" + n.Scalar() + "'";
  if (n.IsSequence()) return "a list";
  if (n.IsMap()) return "a mapping";
  return "a value";
}

std::string fmt_double(double v) {
  std::ostringstream os;
  os.precision(10);
  os << v;
  return os.str();
}

/// The scalar `n` of `p` as a T; anything else fails through p, saying what was `expected`.
template <class T>
T scalar_as(const Params& p, const YAML::Node& n, const std::string& expected) {
  if (!p.is_scalar()) p.fail("expected " + expected + ", got " + describe_value(n) + ".");
  try {
    return n.as<T>();
  } catch (const YAML::Exception&) {
    p.fail("expected " + expected + ", got '" + n.Scalar() + "'.");
  }
}

}  // namespace

std::string closest_match(const std::string& word, const std::vector<std::string>& candidates) {
  std::string best;
  std::size_t best_d = std::string::npos;
  for (const auto& c : candidates) {
    const std::size_t d = edit_distance(word, c);
    if (d < best_d) { best_d = d; best = c; }
  }
  if (best.empty()) return "";
  const std::size_t limit = std::max<std::size_t>(2, word.size() / 3);
  if (best_d <= limit) return best;
  // prefix / containment also counts as close
  if (!word.empty() && (best.find(word) != std::string::npos || word.find(best) != std::string::npos)) return best;
  return "";
}

Params::Params() : impl_(std::make_shared<Impl>()) {
  impl_->doc = std::make_shared<Doc>();
  impl_->present = false;
}
Params::Params(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
Params::~Params() = default;
Params::Params(const Params&) = default;
Params& Params::operator=(const Params&) = default;

namespace {

// yaml-cpp keeps both entries of a repeated key and lookups return the first, so a second
// `integrator:` section would be ignored without a word: refuse it, naming both lines.
void reject_duplicate_keys(const YAML::Node& node, const std::string& source) {
  std::vector<YAML::Node> todo{node};
  while (!todo.empty()) {
    const YAML::Node n = todo.back();
    todo.pop_back();
    if (n.IsMap()) {
      std::map<std::string, int> seen;
      for (auto it = n.begin(); it != n.end(); ++it) {
        const std::string key = it->first.IsScalar() ? it->first.Scalar() : std::string();
        const int line = it->first.Mark().line + 1;
        if (it->first.IsScalar()) {
          const auto [pos, inserted] = seen.emplace(key, line);
          if (!inserted)
            throw InputError(source + ":" + std::to_string(line) + ": duplicate key '" + key +
                             "' (first given at line " + std::to_string(pos->second) +
                             "). Fix: keep one of them; YAML mappings need unique keys.");
        }
        todo.push_back(it->second);
      }
    } else if (n.IsSequence()) {
      for (auto it = n.begin(); it != n.end(); ++it) todo.push_back(*it);
    }
  }
}

}  // namespace

Params Params::from_string(const std::string& yaml, const std::string& source_name) {
  auto doc = std::make_shared<Doc>();
  doc->source = source_name;
  try {
    doc->root = YAML::Load(yaml);
  } catch (const YAML::ParserException& e) {
    std::ostringstream os;
    os << source_name << ":" << (e.mark.line + 1) << ":" << (e.mark.column + 1) << ": YAML syntax error: " << e.msg
       << ". Fix the YAML at that line (check indentation, colons and brackets).";
    throw InputError(os.str());
  }
  if (!doc->root.IsDefined() || doc->root.IsNull()) doc->root = YAML::Node(YAML::NodeType::Map);
  reject_duplicate_keys(doc->root, source_name);
  auto impl = std::make_shared<Impl>();
  impl->doc = doc;
  impl->node = doc->root;
  impl->line = line_of(doc->root, 1);
  return Params(impl);
}

Params Params::from_file(const std::string& path) {
  // Refuse what is not a regular, reasonably sized file before reading it: a directory, a
  // device (/dev/zero would be read forever), a symlink loop or an over-long name.
  std::error_code ec;
  const auto st = std::filesystem::status(path, ec);
  if (ec) {
    std::string why = ec.message();
    if (ec == std::errc::too_many_symbolic_link_levels) why = "a symbolic link loop";
    else if (ec == std::errc::filename_too_long) why = "the name is too long";
    throw InputError(path + ": cannot read the file (" + why + "). Fix: give the path of a YAML file.");
  }
  if (!std::filesystem::exists(st)) throw InputError(path + ": file not found. Fix: check the path.");
  if (std::filesystem::is_directory(st))
    throw InputError(path + ": is a folder, not a file. Fix: give the YAML file inside it (e.g. scenes/hanging_cloth.yaml).");
  if (!std::filesystem::is_regular_file(st))
    throw InputError(path + ": is not a regular file (a device or a pipe). Fix: give the path of a YAML file.");
  // 16 MiB: far above any scene or material file (the largest shipped one is 100 KB), and low
  // enough that a runaway list cannot exhaust memory in the YAML parser (about 150 bytes a node).
  constexpr std::uintmax_t kMaxBytes = 16u << 20;
  const auto bytes = std::filesystem::file_size(path, ec);
  if (!ec && bytes > kMaxBytes)
    throw InputError(path + ": is " + std::to_string(bytes >> 20) + " MiB; YAML inputs are limited to 16 MiB. "
                     "Fix: give large data (meshes) as OBJ files the scene names.");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open file (does it exist, and is it readable?)");
  std::stringstream ss;
  ss << in.rdbuf();
  return from_string(ss.str(), path);
}

bool Params::valid() const { return impl_->present && impl_->node.IsDefined() && !impl_->node.IsNull(); }
bool Params::is_map() const { return valid() && impl_->node.IsMap(); }
bool Params::is_sequence() const { return valid() && impl_->node.IsSequence(); }
bool Params::is_scalar() const { return valid() && impl_->node.IsScalar(); }

bool Params::has(const std::string& key) const {
  if (!is_map()) return false;
  const YAML::Node& n = impl_->node;
  for (auto it = n.begin(); it != n.end(); ++it)
    if (it->first.Scalar() == key) return true;
  return false;
}

std::vector<std::string> Params::keys() const {
  std::vector<std::string> out;
  if (!is_map()) return out;
  for (auto it = impl_->node.begin(); it != impl_->node.end(); ++it) out.push_back(it->first.Scalar());
  return out;
}

std::size_t Params::size() const { return is_sequence() ? impl_->node.size() : 0; }

std::string Params::where() const {
  if (const std::string* o = override_for(*impl_->doc, impl_->path)) return "--set " + *o;
  const std::string& src = impl_->doc->source.empty() ? std::string("<params>") : impl_->doc->source;
  if (impl_->line > 0) return src + ":" + std::to_string(impl_->line);
  return src;
}
std::string Params::path() const { return impl_->path; }
std::string Params::source() const { return impl_->doc->source; }

void Params::fail(const std::string& message) const {
  std::string p = impl_->path.empty() ? "" : impl_->path + ": ";
  throw InputError(where() + ": " + p + message);
}

namespace {
// A read of a key the attached spec does not declare is a bug in the reading code.
const ParamDecl* declared(const ParamSpec* spec, const std::string& key, const std::string& path) {
  if (!spec) return nullptr;
  const ParamDecl* d = spec->find(key);
  if (!d)
    throw std::logic_error("'" + spec->name() + "' reads the key '" + (path.empty() ? key : path + "." + key) +
                           "', which its parameter spec does not declare. Fix (in the code): declare it in the "
                           "spec (loom/param_spec.hpp).");
  return d;
}
}  // namespace

Params Params::with_spec(const ParamSpec* spec) const {
  auto impl = std::make_shared<Impl>(*impl_);
  impl->spec = spec;
  return Params(impl);
}
const ParamSpec* Params::spec() const { return impl_->spec; }

Params Params::child(const std::string& key) const {
  const ParamDecl* decl = declared(impl_->spec, key, impl_->path);
  impl_->doc->asked[impl_->path].insert(key);
  auto impl = std::make_shared<Impl>();
  impl->doc = impl_->doc;
  impl->spec = decl && decl->fields ? decl->fields.get() : nullptr;
  impl->path = join_path(impl_->path, key);
  impl->line = impl_->line;
  impl->present = false;
  if (is_map()) {
    const YAML::Node& n = impl_->node;
    for (auto it = n.begin(); it != n.end(); ++it) {
      if (it->first.Scalar() == key) {
        impl->node = it->second;
        impl->present = true;
        impl->line = line_of(it->second, line_of(it->first, impl_->line));
        break;
      }
    }
  }
  return Params(impl);
}

Params Params::at(std::size_t i) const {
  auto impl = std::make_shared<Impl>();
  impl->doc = impl_->doc;
  impl->path = impl_->path + "[" + std::to_string(i) + "]";
  impl->line = impl_->line;
  impl->present = false;
  if (is_sequence() && i < impl_->node.size()) {
    impl->node = impl_->node[i];
    impl->present = true;
    impl->line = line_of(impl->node, impl_->line);
  }
  return Params(impl);
}

double Params::as_double() const { return scalar_as<double>(*this, impl_->node, "a number"); }

std::int64_t Params::as_int() const { return scalar_as<long long>(*this, impl_->node, "an integer"); }

bool Params::as_bool() const { return scalar_as<bool>(*this, impl_->node, "true or false"); }

std::string Params::as_string() const {
  if (!is_scalar()) fail("expected a text value, got " + describe_value(impl_->node) + ".");
  return impl_->node.Scalar();
}

std::vector<double> Params::as_doubles() const {
  if (!is_sequence()) fail("expected a list of numbers like [0, -9.81, 0], got " + describe_value(impl_->node) + ".");
  std::vector<double> out;
  for (std::size_t i = 0; i < size(); ++i) out.push_back(at(i).as_double());
  return out;
}

double Params::get(const std::string& key, double def) const {
  Params c = child(key);
  return c.valid() ? c.as_double() : def;
}
std::int64_t Params::get(const std::string& key, std::int64_t def) const {
  Params c = child(key);
  return c.valid() ? c.as_int() : def;
}
int Params::get(const std::string& key, int def) const {
  Params c = child(key);
  if (!c.valid()) return def;
  const std::int64_t v = c.as_int();
  if (v < -2147483647LL || v > 2147483647LL) c.fail("integer out of range.");
  return static_cast<int>(v);
}
bool Params::get(const std::string& key, bool def) const {
  Params c = child(key);
  return c.valid() ? c.as_bool() : def;
}
std::string Params::get(const std::string& key, const std::string& def) const {
  Params c = child(key);
  return c.valid() ? c.as_string() : def;
}
std::string Params::get(const std::string& key, const char* def) const { return get(key, std::string(def)); }

double Params::require_double(const std::string& key) const {
  Params c = child(key);
  if (!c.valid()) fail("missing required key '" + key + "' (a number).");
  return c.as_double();
}
std::int64_t Params::require_int(const std::string& key) const {
  Params c = child(key);
  if (!c.valid()) fail("missing required key '" + key + "' (an integer).");
  return c.as_int();
}
std::string Params::require_string(const std::string& key) const {
  Params c = child(key);
  if (!c.valid()) fail("missing required key '" + key + "'.");
  return c.as_string();
}

double Params::get_positive(const std::string& key, double def) const {
  Params c = child(key);
  if (!c.valid()) return def;
  const double v = c.as_double();
  if (!std::isfinite(v) || v <= 0) c.fail("must be a finite number > 0 (got " + fmt_double(v) + "). Fix: give a positive value.");
  return v;
}
double Params::get_nonnegative(const std::string& key, double def) const {
  Params c = child(key);
  if (!c.valid()) return def;
  const double v = c.as_double();
  if (!std::isfinite(v) || v < 0) c.fail("must be a finite number >= 0 (got " + fmt_double(v) + "). Fix: give a value >= 0.");
  return v;
}
double Params::get_in_range(const std::string& key, double def, double lo, double hi) const {
  Params c = child(key);
  if (!c.valid()) return def;
  const double v = c.as_double();
  if (!std::isfinite(v) || v < lo || v > hi)
    c.fail("must be in [" + fmt_double(lo) + ", " + fmt_double(hi) + "] (got " + fmt_double(v) + ").");
  return v;
}
std::string Params::get_choice(const std::string& key, const std::string& def,
                               const std::vector<std::string>& choices) const {
  Params c = child(key);
  if (!c.valid()) return def;
  const std::string v = c.as_string();
  if (std::find(choices.begin(), choices.end(), v) != choices.end()) return v;
  std::string list;
  for (const auto& s : choices) list += (list.empty() ? "" : ", ") + s;
  std::string hint = closest_match(v, choices);
  c.fail("unknown value '" + v + "'" + (hint.empty() ? "" : " (did you mean '" + hint + "'?)") + ". Choose one of: " + list + ".");
}

void Params::mark_used(const std::string& key) const {
  declared(impl_->spec, key, impl_->path);
  impl_->doc->asked[impl_->path].insert(key);
}

void Params::check_unused(const std::vector<std::string>& also_known) const {
  if (!is_map()) return;
  const auto& asked = impl_->doc->asked[impl_->path];
  std::vector<std::string> known(asked.begin(), asked.end());
  known.insert(known.end(), also_known.begin(), also_known.end());
  if (impl_->spec)  // declared keys are suggestions for a typo even when not read
    for (const auto& d : impl_->spec->decls())
      if (d.backends.empty() || asked.count(d.name)) known.push_back(d.name);
  for (auto it = impl_->node.begin(); it != impl_->node.end(); ++it) {
    const std::string k = it->first.Scalar();
    if (asked.count(k) || std::find(also_known.begin(), also_known.end(), k) != also_known.end()) continue;
    if (it->second.IsNull()) continue;  // `key: null` (or --set key=null) removes a key
    const int key_line = line_of(it->first, impl_->line);
    const std::string& key_src = impl_->doc->source.empty() ? std::string("<params>") : impl_->doc->source;
    // Where the key was written: the file's line, or the --set that added it.
    const std::string* set_by = override_for(*impl_->doc, join_path(impl_->path, k));
    const std::string key_where = set_by ? "--set " + *set_by : key_src + ":" + std::to_string(key_line);
    if (const ParamDecl* d = impl_->spec ? impl_->spec->find(k) : nullptr; d && !d->backends.empty()) {
      std::string list;
      for (const auto& b : d->backends) list += (list.empty() ? "" : ", ") + b;
      throw InputError(key_where + ": key '" + k + "'" +
                       (impl_->path.empty() ? "" : " in '" + impl_->path + "'") + " is honoured only by the " + list +
                       " backend of '" + impl_->spec->name() + "'. Fix: remove it, or set backend: " +
                       d->backends.front() + ".");
    }
    std::string msg = "unknown key '" + k + "'";
    if (!impl_->path.empty()) msg += " in '" + impl_->path + "'";
    const std::string hint = closest_match(k, known);
    if (!hint.empty()) msg += " (did you mean '" + hint + "'?)";
    std::sort(known.begin(), known.end());
    known.erase(std::unique(known.begin(), known.end()), known.end());
    if (!known.empty()) {
      msg += ". Known keys here: ";
      for (std::size_t i = 0; i < known.size(); ++i) msg += (i ? ", " : "") + known[i];
    }
    msg += ".";
    throw InputError(key_where + ": " + msg);
  }
}

void Params::set_path(const std::string& dotted_key, const std::string& value_yaml) {
  if (dotted_key.empty()) throw InputError("--set: empty key. Use --set section.key=value, e.g. --set integrator.dt=0.0005");
  YAML::Node value;
  try {
    value = YAML::Load(value_yaml);
  } catch (const YAML::Exception& e) {
    throw InputError("--set " + dotted_key + "=" + value_yaml + ": the value is not valid YAML (" + e.what() + ")");
  }
  if (!value.IsDefined() || (value.IsNull() && value_yaml.find_first_not_of(" \t") == std::string::npos))
    value = YAML::Node(value_yaml);  // `--set key=` sets an empty text; `key=null` removes the key
  if (value.IsNull()) {
    // Only an explicit null removes a key: `&a` or `*a` alone parse as null too.
    const auto b = value_yaml.find_first_not_of(" \t"), e = value_yaml.find_last_not_of(" \t");
    const std::string t = b == std::string::npos ? std::string() : value_yaml.substr(b, e - b + 1);
    if (t != "null" && t != "~" && t != "Null" && t != "NULL")
      throw InputError("--set " + dotted_key + "=" + value_yaml + ": the value is not a YAML value (an anchor or alias "
                       "alone). Fix: give a value, or " + dotted_key + "=null to remove the key.");
  }
  if (impl_->node.IsDefined() && !impl_->node.IsNull() && !impl_->node.IsMap())
    throw InputError(source() + ": the file is not a YAML mapping, so --set " + dotted_key +
                     " has nothing to set. Fix: a scene is a mapping with mesh, material, integrator, ... sections.");
  std::vector<std::string> parts;
  std::stringstream ss(dotted_key);
  std::string part;
  while (std::getline(ss, part, '.')) {
    if (part.empty()) throw InputError("--set " + dotted_key + ": empty component in the dotted key.");
    parts.push_back(part);
  }
  // Navigate with non-const access, creating maps on the way. yaml-cpp nodes are handles,
  // so we keep a chain of handles and assign into the last one. A component that meets a list
  // is an entry's index, from 0 (colliders.0.radius). ppath: the reached node's path as Params
  // names it (colliders[0].radius), for the errors that name this --set later.
  const std::string set_text = "--set " + dotted_key + "=" + value_yaml;
  std::string ppath = impl_->path;
  const auto prefix = [&](std::size_t n) {  // the first n components, dotted
    std::string t;
    for (std::size_t k = 0; k < n; ++k) t += (k ? "." : "") + parts[k];
    return t;
  };
  const auto entry = [&](const YAML::Node& list, std::size_t i) -> std::size_t {
    const std::string& c = parts[i];
    const std::string where = i == 0 ? std::string("the scene") : "'" + prefix(i) + "'";
    if (c.empty() || c.size() > 9 || c.find_first_not_of("0123456789") != std::string::npos)
    {
      std::string rest;  // the components after this one
      for (std::size_t k = i + 1; k < parts.size(); ++k) rest += "." + parts[k];
      throw InputError(set_text + ": " + where + " is a list, so '" + c + "' must be the index of one of its " +
                       std::to_string(list.size()) + " entries, from 0. Fix: e.g. --set " + prefix(i) + ".0" + rest +
                       "=" + value_yaml + ", or set the whole list.");
    }
    const std::size_t k = static_cast<std::size_t>(std::stoul(c));
    if (k >= list.size())
      throw InputError(set_text + ": " + where + " has " + std::to_string(list.size()) + " entr" +
                       (list.size() == 1 ? "y" : "ies") + " (indices from 0), so there is no entry " + c +
                       ". Fix: use an index below " + std::to_string(list.size()) + ", or set the whole list.");
    return k;
  };
  std::vector<YAML::Node> chain{impl_->node};
  std::string created;  // the path of the first section this --set had to create, if any
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) {
    YAML::Node cur = chain.back();
    YAML::Node next;
    if (cur.IsSequence()) {
      const std::size_t k = entry(cur, i);
      next = cur[k];
      ppath += "[" + std::to_string(k) + "]";
    } else {
      if (!cur.IsMap() && !cur.IsNull() && cur.IsDefined())
        throw InputError(set_text + ": '" + parts[i] + "' is inside a value that is not a mapping.");
      next = cur[parts[i]];
      ppath = join_path(ppath, parts[i]);
      if (!next.IsDefined() || next.IsNull()) {
        cur[parts[i]] = YAML::Node(YAML::NodeType::Map);
        next = cur[parts[i]];
        if (created.empty()) created = ppath;   // this --set made the section: errors in it name the --set
      }
    }
    if (!next.IsMap() && !next.IsSequence())
      throw InputError("--set " + dotted_key + ": '" + prefix(i + 1) +
                       "' is a value, not a section or a list; cannot set a key inside it.");
    chain.push_back(next);
  }
  YAML::Node last = chain.back();
  if (last.IsSequence()) {
    const std::size_t k = entry(last, parts.size() - 1);
    if (value.IsNull())
      throw InputError(set_text + ": an entry of a list cannot be removed by --set. Fix: set the whole list, e.g. --set " +
                       prefix(parts.size() - 1) + "=[...].");
    last[k] = value;
    ppath += "[" + std::to_string(k) + "]";
  } else {
    last[parts.back()] = value;
    ppath = join_path(ppath, parts.back());
  }
  impl_->doc->overrides.emplace_back(created.empty() ? ppath : created, dotted_key + "=" + value_yaml);
}

std::string Params::dump(bool flow) const {
  if (!impl_->present) return "";
  YAML::Emitter out;
  if (flow) {
    out.SetSeqFormat(YAML::Flow);
    out.SetMapFormat(YAML::Flow);
  }
  out << impl_->node;
  return out.c_str();
}

}  // namespace loom
