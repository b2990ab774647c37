// Scene files: parsing and validation (see scene.hpp and docs/scene-format.md).
//
// Outline: the text is parsed into a JSON DOM by nlohmann's SAX parser through a small
// handler that also records duplicate keys with their path; numbers that overflow a double
// (1e999) are turned into marked strings and the text re-parsed, so that they become field
// errors instead of stopping the parse. The DOM is then walked section by section with
// readers that check type, range and presence, remember which keys each object was asked
// for (the rest are unknown keys, reported with a "did you mean"), and append every
// problem to one error list. Cross references and file contents are checked last; the
// scene is returned only when the list is empty.
#include "scene/scene.hpp"

#include "particles/material.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "common/hash.hpp"
#include "scene/mesh.hpp"

namespace sandpatch {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr double kPi = 3.14159265358979323846;
// Prefix of the string that stands in for a number too large for a double.
constexpr const char* kOverflowMarker = "\x01sandpatch-overflow:";

// ---------------------------------------------------------------------------------------
// Small text helpers

std::string fmt_num(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", x);
  return buf;
}

std::string json_quote(const std::string& s) { return json(s).dump(); }

std::string lower(std::string s) {
  for (auto& ch : s) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return s;
}

// Optimal string alignment distance (Damerau–Levenshtein without repeated edits of a
// substring): insertions, deletions, substitutions and adjacent transpositions cost 1.
std::size_t edit_distance(const std::string& a, const std::string& b) {
  const std::size_t n = a.size(), m = b.size();
  std::vector<std::vector<std::size_t>> d(n + 1, std::vector<std::size_t>(m + 1));
  for (std::size_t i = 0; i <= n; ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= m; ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= n; ++i) {
    for (std::size_t j = 1; j <= m; ++j) {
      const std::size_t cost = a[i - 1] == b[j - 1] ? 0 : 1;
      d[i][j] = std::min({d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1]) {
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
      }
    }
  }
  return d[n][m];
}

// The closest candidate within max(2, len/3) edits (case-insensitive), or "".
std::string closest(const std::string& word, const std::vector<std::string>& candidates) {
  const std::string w = lower(word);
  const std::size_t threshold = std::max<std::size_t>(2, w.size() / 3);
  std::string best;
  std::size_t best_d = threshold + 1;
  for (const auto& c : candidates) {
    const std::size_t d = edit_distance(w, lower(c));
    if (d < best_d) best_d = d, best = c;
  }
  return best;
}

std::string did_you_mean(const std::string& word, const std::vector<std::string>& candidates) {
  const std::string best = closest(word, candidates);
  return best.empty() ? std::string() : "did you mean '" + best + "'?";
}

std::string join(const std::vector<std::string>& v, const std::string& sep = ", ") {
  std::string s;
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? sep : "") + v[i];
  return s;
}

// 1-based line and column of the character at 0-based byte `index` of `text`.
std::pair<std::size_t, std::size_t> line_column(const std::string& text, std::size_t index) {
  index = std::min(index, text.size());
  std::size_t line = 1, col = 1;
  for (std::size_t i = 0; i < index; ++i) {
    if (text[i] == '\n') ++line, col = 1;
    else ++col;
  }
  return {line, col};
}

// ---------------------------------------------------------------------------------------
// JSON text → DOM

// nlohmann's DOM builder plus the path of the value being built, for duplicate keys.
class SaxBuilder : public nlohmann::detail::json_sax_dom_parser<json> {
  using Base = nlohmann::detail::json_sax_dom_parser<json>;

 public:
  explicit SaxBuilder(json& out) : Base(out, /*allow_exceptions=*/false) {}

  struct Failure {
    std::size_t byte = 0;  // chars read when it failed (1-based index of the last one)
    std::string token;     // last token read
    int id = 0;            // nlohmann exception id (101 syntax, 406 number overflow)
    std::string what;
  };
  std::optional<Failure> failure;
  std::vector<std::string> duplicate_keys;  // field paths

  bool null() { value(); return Base::null(); }
  bool boolean(bool v) { value(); return Base::boolean(v); }
  bool number_integer(number_integer_t v) { value(); return Base::number_integer(v); }
  bool number_unsigned(number_unsigned_t v) { value(); return Base::number_unsigned(v); }
  bool number_float(number_float_t v, const string_t& s) { value(); return Base::number_float(v, s); }
  bool string(string_t& v) { value(); return Base::string(v); }
  bool binary(binary_t& v) { value(); return Base::binary(v); }
  bool start_object(std::size_t n) {
    value();
    frames_.push_back({false, {}, -1, {}});
    return Base::start_object(n);
  }
  bool key(string_t& k) {
    auto& f = frames_.back();
    f.key = k;
    if (!f.keys.insert(k).second) duplicate_keys.push_back(path());
    return Base::key(k);
  }
  bool end_object() { frames_.pop_back(); return Base::end_object(); }
  bool start_array(std::size_t n) {
    value();
    frames_.push_back({true, {}, -1, {}});
    return Base::start_array(n);
  }
  bool end_array() { frames_.pop_back(); return Base::end_array(); }
  template <class Exception>
  bool parse_error(std::size_t byte, const std::string& token, const Exception& ex) {
    failure = Failure{byte, token, ex.id, ex.what()};
    return false;
  }

  // "bodies[1].shape" of the value last started.
  std::string path() const {
    std::string p;
    for (const auto& f : frames_) {
      if (f.is_array) p += "[" + std::to_string(f.index) + "]";
      else p += (p.empty() ? "" : ".") + f.key;
    }
    return p;
  }

 private:
  struct Frame {
    bool is_array;
    std::string key;
    int index;
    std::set<std::string> keys;
  };
  void value() {
    if (!frames_.empty() && frames_.back().is_array) ++frames_.back().index;
  }
  std::vector<Frame> frames_;
};

struct ParsedText {
  json root;
  std::vector<std::string> duplicate_keys;
  std::optional<Error> error;
};

ParsedText parse_json_text(std::string text, const std::string& file) {
  ParsedText out;
  // Each pass either succeeds, fails on syntax, or replaces one overflowing number by a
  // marked string and tries again.
  for (int pass = 0; pass < 10000; ++pass) {
    json root;
    SaxBuilder sax(root);
    bool ok = false;
    try {
      ok = json::sax_parse(text, &sax, json::input_format_t::json, /*strict=*/true);
    } catch (const std::exception& e) {
      sax.failure = SaxBuilder::Failure{0, "", 0, e.what()};
    }
    if (ok && !sax.failure) {
      out.root = std::move(root);
      out.duplicate_keys = std::move(sax.duplicate_keys);
      return out;
    }
    const auto f = sax.failure.value_or(SaxBuilder::Failure{text.size(), "", 0, "parse failed"});
    const std::size_t len = f.token.size();
    if (f.id == 406 && len > 0 && f.byte >= len && text.compare(f.byte - len, len, f.token) == 0) {
      text.replace(f.byte - len, len, json_quote(kOverflowMarker + f.token));
      continue;
    }
    // Syntax error: report the line and column of the last character read.
    const auto [line, col] = line_column(text, f.byte == 0 ? 0 : f.byte - 1);
    std::string what = f.what;
    if (const auto p = what.find(": "); what.starts_with("[json.exception") && p != std::string::npos) {
      what = what.substr(p + 2);
    }
    out.error = Error{file, "line " + std::to_string(line) + ", column " + std::to_string(col),
                      "", "must be valid JSON (RFC 8259)", what};
    return out;
  }
  out.error = Error{file, "", "", "must be valid JSON", "too many overflowing numbers"};
  return out;
}

bool is_overflow_marker(const json& v) {
  return v.is_string() && v.get_ref<const std::string&>().starts_with(kOverflowMarker);
}

// The value as the user wrote it (compact JSON, long values shortened).
std::string show(const json& v) {
  if (is_overflow_marker(v)) return v.get_ref<const std::string&>().substr(std::string(kOverflowMarker).size());
  std::string s = v.dump();
  if (s.size() > 80) s = s.substr(0, 77) + "...";
  return s;
}

// ---------------------------------------------------------------------------------------
// Validation context and readers

struct Range {
  double lo, hi;
  bool lo_open = false, hi_open = false;
  const char* unit = "";

  bool contains(double x) const {
    return (lo_open ? x > lo : x >= lo) && (hi_open ? x < hi : x <= hi);
  }
  std::string describe() const {
    std::string s = std::string(lo_open ? "(" : "[") + fmt_num(lo) + ", " + fmt_num(hi) + (hi_open ? ")" : "]");
    if (*unit) s += std::string(" ") + unit;
    return s;
  }
};

Range closed(double lo, double hi, const char* unit) { return {lo, hi, false, false, unit}; }
Range positive(double hi, const char* unit) { return {0.0, hi, true, false, unit}; }

struct Ctx {
  std::string file;
  fs::path base_dir;
  std::vector<Error> errors;
  std::vector<std::string> referenced_files;  // resolved, in order, hashed with the scene

  void error(std::string field, std::string value, std::string allowed, std::string detail = {}) {
    errors.push_back({file, std::move(field), std::move(value), std::move(allowed), std::move(detail)});
  }
  void missing(const std::string& field, const std::string& what) {
    error(field, "", "missing required field: " + what);
  }
};

std::string type_detail(const json& v) { return std::string("got ") + (v.is_null() ? "null" : v.type_name()); }

std::optional<double> read_number(Ctx& c, const json& v, const std::string& f, const Range& r) {
  const std::string allowed = "must be a finite number in " + r.describe();
  if (is_overflow_marker(v)) {
    c.error(f, show(v), allowed, "the number is too large for a double (infinite)");
    return std::nullopt;
  }
  if (v.is_string()) {
    static const std::set<std::string> non_finite = {"nan", "+nan", "-nan", "inf", "+inf", "-inf",
                                                     "infinity", "+infinity", "-infinity"};
    const std::string s = lower(v.get<std::string>());
    if (non_finite.contains(s)) {
      c.error(f, show(v), allowed, "NaN and infinity are not allowed");
    } else {
      c.error(f, show(v), allowed, "got a string; write the number without quotes");
    }
    return std::nullopt;
  }
  if (!v.is_number()) {
    c.error(f, show(v), allowed, type_detail(v));
    return std::nullopt;
  }
  const double x = v.get<double>();
  if (!std::isfinite(x)) {
    c.error(f, show(v), allowed, "NaN and infinity are not allowed");
    return std::nullopt;
  }
  if (!r.contains(x)) {
    c.error(f, show(v), allowed, x < 0 && r.lo >= 0 ? "negative values are not allowed" : "");
    return std::nullopt;
  }
  return x;
}

// Integers: JSON integers, or numbers with no fractional part (1e6).
std::optional<double> read_integer(Ctx& c, const json& v, const std::string& f, double lo, double hi,
                                   const char* unit = "") {
  const Range r = closed(lo, hi, unit);
  const std::string allowed = "must be an integer in " + r.describe();
  if (v.is_number_integer()) {
    // Unsigned values above 2^63 and big negatives compare correctly as doubles here.
    const double x = v.is_number_unsigned() ? static_cast<double>(v.get<std::uint64_t>())
                                            : static_cast<double>(v.get<std::int64_t>());
    if (!r.contains(x)) {
      c.error(f, show(v), allowed, x < 0 && lo >= 0 ? "negative values are not allowed" : "");
      return std::nullopt;
    }
    return x;
  }
  if (v.is_number_float() && std::isfinite(v.get<double>()) && std::floor(v.get<double>()) == v.get<double>()) {
    const double x = v.get<double>();
    if (!r.contains(x)) {
      c.error(f, show(v), allowed, x < 0 && lo >= 0 ? "negative values are not allowed" : "");
      return std::nullopt;
    }
    return x;
  }
  if (v.is_number_float() || is_overflow_marker(v)) {
    c.error(f, show(v), allowed, is_overflow_marker(v) ? "the number is too large" : "got a fraction");
  } else {
    c.error(f, show(v), allowed, v.is_string() ? "got a string; write the number without quotes" : type_detail(v));
  }
  return std::nullopt;
}

std::optional<std::uint64_t> read_u64(Ctx& c, const json& v, const std::string& f) {
  const std::string allowed = "must be an integer in [0, 18446744073709551615]";
  if (v.is_number_unsigned()) return v.get<std::uint64_t>();
  if (v.is_number_integer()) {
    c.error(f, show(v), allowed, "negative values are not allowed");
    return std::nullopt;
  }
  if (v.is_number_float() && std::isfinite(v.get<double>()) && v.get<double>() >= 0 &&
      v.get<double>() < 1.8e19 && std::floor(v.get<double>()) == v.get<double>()) {
    return static_cast<std::uint64_t>(v.get<double>());
  }
  c.error(f, show(v), allowed, v.is_string() ? "got a string; write the number without quotes" : type_detail(v));
  return std::nullopt;
}

std::optional<std::string> read_string(Ctx& c, const json& v, const std::string& f, bool non_empty = true) {
  if (!v.is_string() || is_overflow_marker(v)) {
    c.error(f, show(v), "must be a string", type_detail(v));
    return std::nullopt;
  }
  std::string s = v.get<std::string>();
  if (non_empty && s.empty()) {
    c.error(f, show(v), "must be a non-empty string");
    return std::nullopt;
  }
  return s;
}

std::optional<bool> read_bool(Ctx& c, const json& v, const std::string& f) {
  if (!v.is_boolean()) {
    c.error(f, show(v), "must be true or false", v.is_string() ? "got a string; write true or false without quotes"
                                                                 : type_detail(v));
    return std::nullopt;
  }
  return v.get<bool>();
}

// A fixed-length array of numbers, each checked against `r`.
template <std::size_t N>
std::optional<std::array<double, N>> read_numbers(Ctx& c, const json& v, const std::string& f, const Range& r) {
  if (!v.is_array() || v.size() != N) {
    c.error(f, show(v), "must be an array of " + std::to_string(N) + " numbers in " + r.describe(),
            v.is_array() ? "got " + std::to_string(v.size()) + " elements" : type_detail(v));
    return std::nullopt;
  }
  std::array<double, N> out{};
  bool ok = true;
  for (std::size_t i = 0; i < N; ++i) {
    const auto x = read_number(c, v[i], f + "[" + std::to_string(i) + "]", r);
    if (x) out[i] = *x;
    else ok = false;
  }
  return ok ? std::optional<std::array<double, N>>(out) : std::nullopt;
}

// One of a fixed set of words; index into `choices`.
std::optional<int> read_enum(Ctx& c, const json& v, const std::string& f, const std::vector<std::string>& choices) {
  const std::string allowed = "must be one of: " + join(choices);
  if (!v.is_string() || is_overflow_marker(v)) {
    c.error(f, show(v), allowed, type_detail(v));
    return std::nullopt;
  }
  const std::string s = v.get<std::string>();
  for (std::size_t i = 0; i < choices.size(); ++i) {
    if (choices[i] == s) return static_cast<int>(i);
  }
  c.error(f, show(v), allowed, did_you_mean(s, choices));
  return std::nullopt;
}

// An object being read: remembers the keys asked for, so that the rest are unknown keys.
class Obj {
 public:
  Obj(Ctx& c, const json& j, std::string path) : c_(c), j_(j), path_(std::move(path)) {
    valid_ = j.is_object();
    if (!valid_) c_.error(path_.empty() ? "(top level)" : path_, show(j), "must be an object { ... }", type_detail(j));
  }
  bool valid() const { return valid_; }
  const std::string& path() const { return path_; }
  std::string at(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

  // The value of `key`, or nullptr when absent (or when this is not an object).
  const json* get(const std::string& key) {
    if (std::find(known_.begin(), known_.end(), key) == known_.end()) known_.push_back(key);
    if (!valid_) return nullptr;
    const auto it = j_.find(key);
    return it == j_.end() ? nullptr : &*it;
  }
  bool has(const std::string& key) { return get(key) != nullptr; }
  const json* require(const std::string& key, const std::string& what) {
    const json* v = get(key);
    if (!v && valid_) c_.missing(at(key), what);
    return v;
  }

  // Optional fields from the knob table (common/knobs.hpp): its range and unit.
  void knob(const std::string& key, double& out, const knobs::Knob& k) {
    number(key, out, Range{k.lo, k.hi, k.lo_open, k.hi_open, k.unit});
  }
  void knob(const std::string& key, int& out, const knobs::Knob& k) { integer(key, out, k.lo, k.hi, k.unit); }

  // Optional fields: `out` keeps its default when absent or invalid.
  void number(const std::string& key, double& out, const Range& r) {
    if (const json* v = get(key)) {
      if (auto x = read_number(c_, *v, at(key), r)) out = *x;
    }
  }
  std::optional<double> number_opt(const std::string& key, const Range& r) {
    const json* v = get(key);
    return v ? read_number(c_, *v, at(key), r) : std::nullopt;
  }
  bool number_req(const std::string& key, double& out, const Range& r) {
    const json* v = require(key, "a number in " + r.describe());
    if (!v) return false;
    const auto x = read_number(c_, *v, at(key), r);
    if (x) out = *x;
    return x.has_value();
  }
  void integer(const std::string& key, int& out, double lo, double hi, const char* unit = "") {
    if (const json* v = get(key)) {
      if (auto x = read_integer(c_, *v, at(key), lo, hi, unit)) out = static_cast<int>(*x);
    }
  }
  bool integer_req(const std::string& key, int& out, double lo, double hi) {
    const json* v = require(key, "an integer in [" + fmt_num(lo) + ", " + fmt_num(hi) + "]");
    if (!v) return false;
    const auto x = read_integer(c_, *v, at(key), lo, hi);
    if (x) out = static_cast<int>(*x);
    return x.has_value();
  }
  void u64(const std::string& key, std::uint64_t& out) {
    if (const json* v = get(key)) {
      if (auto x = read_u64(c_, *v, at(key))) out = *x;
    }
  }
  void boolean(const std::string& key, bool& out) {
    if (const json* v = get(key)) {
      if (auto x = read_bool(c_, *v, at(key))) out = *x;
    }
  }
  void string(const std::string& key, std::string& out, bool non_empty = true) {
    if (const json* v = get(key)) {
      if (auto x = read_string(c_, *v, at(key), non_empty)) out = *x;
    }
  }
  bool string_req(const std::string& key, std::string& out, const std::string& what) {
    const json* v = require(key, what);
    if (!v) return false;
    const auto x = read_string(c_, *v, at(key));
    if (x) out = *x;
    return x.has_value();
  }
  void vec3(const std::string& key, Vec3d& out, const Range& r) {
    if (const json* v = get(key)) {
      if (auto x = read_numbers<3>(c_, *v, at(key), r)) out = *x;
    }
  }
  bool vec3_req(const std::string& key, Vec3d& out, const Range& r) {
    const json* v = require(key, "an array of 3 numbers in " + r.describe());
    if (!v) return false;
    const auto x = read_numbers<3>(c_, *v, at(key), r);
    if (x) out = *x;
    return x.has_value();
  }
  template <class E>
  void enumeration(const std::string& key, E& out, const std::vector<std::string>& choices) {
    if (const json* v = get(key)) {
      if (auto x = read_enum(c_, *v, at(key), choices)) out = static_cast<E>(*x);
    }
  }
  template <class E>
  bool enumeration_req(const std::string& key, E& out, const std::vector<std::string>& choices) {
    const json* v = require(key, "one of: " + join(choices));
    if (!v) return false;
    const auto x = read_enum(c_, *v, at(key), choices);
    if (x) out = static_cast<E>(*x);
    return x.has_value();
  }

  // At most one of two alternative keys; true when both were given (and reported).
  bool both(const std::string& a, const std::string& b) {
    if (has(a) && has(b)) {
      c_.error(at(b), show(*get(b)), "give only one of '" + a + "' and '" + b + "'",
               "'" + a + "' is given too");
      return true;
    }
    return false;
  }

  // Reports every key that no reader asked for.
  void finish() {
    if (!valid_) return;
    for (const auto& [key, v] : j_.items()) {
      if (std::find(known_.begin(), known_.end(), key) != known_.end()) continue;
      std::vector<std::string> sorted = known_;
      std::sort(sorted.begin(), sorted.end());
      c_.error(at(key), show(v), "unknown key; allowed here: " + join(sorted), did_you_mean(key, known_));
    }
  }

 private:
  Ctx& c_;
  const json& j_;
  std::string path_;
  bool valid_ = false;
  std::vector<std::string> known_;
};

// Calls `each(element, path)` for every element of an array field; false if not an array.
template <class F>
bool for_each_element(Ctx& c, const json& v, const std::string& f, F&& each) {
  if (!v.is_array()) {
    c.error(f, show(v), "must be an array [ ... ]", type_detail(v));
    return false;
  }
  for (std::size_t i = 0; i < v.size(); ++i) each(v[i], f + "[" + std::to_string(i) + "]");
  return true;
}

// Times in seconds: ascending, each in [0, 1e6].
std::vector<double> read_times(Ctx& c, const json& v, const std::string& f) {
  std::vector<double> times;
  for_each_element(c, v, f, [&](const json& e, const std::string& p) {
    if (auto t = read_number(c, e, p, closed(0.0, 1e6, "s"))) {
      if (!times.empty() && *t <= times.back()) {
        c.error(p, show(e), "times must be strictly ascending", "follows " + fmt_num(times.back()));
      }
      times.push_back(*t);
    }
  });
  if (v.is_array() && v.empty()) c.error(f, "[]", "must hold at least one time (s)");
  return times;
}

// ---------------------------------------------------------------------------------------
// Files

std::string resolve(const Ctx& c, const std::string& written) {
  fs::path p(written);
  if (p.is_relative()) p = c.base_dir / p;
  return p.lexically_normal().string();
}

// True when the file exists and opens; otherwise an error on `field`.
bool check_readable(Ctx& c, const std::string& field, const std::string& written, const std::string& resolved,
                    const std::string& what) {
  std::error_code ec;
  const std::string allowed = "must name an existing, readable " + what + " (relative paths are relative to the scene file)";
  if (!fs::exists(resolved, ec)) {
    c.error(field, json_quote(written), allowed, "file not found: " + resolved);
    return false;
  }
  if (!fs::is_regular_file(resolved, ec)) {
    c.error(field, json_quote(written), allowed, "not a regular file: " + resolved);
    return false;
  }
  std::ifstream in(resolved, std::ios::binary);
  char probe;
  if (!in.good() || (fs::file_size(resolved, ec) > 0 && !in.read(&probe, 1))) {
    c.error(field, json_quote(written), allowed, "file cannot be read: " + resolved);
    return false;
  }
  c.referenced_files.push_back(resolved);
  return true;
}

std::string read_head(const std::string& path, std::size_t n) {
  std::ifstream in(path, std::ios::binary);
  std::string s(n, '\0');
  in.read(s.data(), static_cast<std::streamsize>(n));
  s.resize(static_cast<std::size_t>(in.gcount()));
  return s;
}

// Cheap content checks that catch a wrong format before any loader runs.
void check_png16(Ctx& c, const std::string& field, const std::string& written, const std::string& path) {
  // Signature, then the IHDR chunk: width, height, bit depth (byte 24), colour type (byte 25).
  const std::string h = read_head(path, 29);
  static const std::string sig = "\x89PNG\r\n\x1a\n";
  const std::string allowed = "must be a greyscale PNG (16-bit for full precision; 1/2/4/8-bit accepted)";
  if (h.size() < 29 || h.compare(0, 8, sig) != 0 || h.compare(12, 4, "IHDR") != 0) {
    c.error(field, json_quote(written), allowed, path + " is not a PNG file");
    return;
  }
  const int bit_depth = static_cast<unsigned char>(h[24]);
  const int colour_type = static_cast<unsigned char>(h[25]);
  const bool grey = colour_type == 0 || colour_type == 4;  // greyscale, greyscale + alpha (ignored)
  if (!grey) {
    c.error(field, json_quote(written), allowed,
            path + " has colour type " + std::to_string(colour_type) + " (colour or palette), not greyscale");
  } else if (bit_depth != 1 && bit_depth != 2 && bit_depth != 4 && bit_depth != 8 && bit_depth != 16) {
    c.error(field, json_quote(written), allowed, path + " has an invalid bit depth " + std::to_string(bit_depth));
  }
}

void check_raw_f32(Ctx& c, const std::string& field, const std::string& written, const std::string& path, int nx,
                   int nz) {
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  const auto expected = static_cast<std::uintmax_t>(nx) * static_cast<std::uintmax_t>(nz) * 4u;
  if (!ec && size != expected) {
    c.error(field, json_quote(written),
            "must hold samples_x × samples_z = " + std::to_string(nx) + " × " + std::to_string(nz) +
                " little-endian float32 values (" + std::to_string(expected) + " bytes)",
            path + " has " + std::to_string(size) + " bytes");
  }
}

void check_esri_ascii(Ctx& c, const std::string& field, const std::string& written, const std::string& path) {
  std::istringstream head(read_head(path, 512));
  std::string word;
  head >> word;
  static const std::set<std::string> keys = {"ncols", "nrows", "xllcorner", "xllcenter",
                                             "yllcorner", "yllcenter", "cellsize", "nodata_value"};
  if (!keys.contains(lower(word))) {
    c.error(field, json_quote(written), "must be an ESRI ASCII grid (a header of ncols, nrows, ... first)",
            path + " starts with " + json_quote(word.substr(0, 20)));
  }
}

bool valid_pattern(Ctx& c, const std::string& field, const std::string& pattern,
                   const std::vector<std::string>& placeholders) {
  const std::string allowed = "must be a relative file name without '..'; placeholders: " + join(placeholders);
  const fs::path p(pattern);
  if (p.is_absolute()) {
    c.error(field, json_quote(pattern), allowed, "outputs are written inside the output directory");
    return false;
  }
  for (const auto& part : p) {
    if (part == "..") {
      c.error(field, json_quote(pattern), allowed, "outputs are written inside the output directory");
      return false;
    }
  }
  for (std::size_t i = 0; i < pattern.size(); ++i) {
    if (pattern[i] == '}') {
      c.error(field, json_quote(pattern), allowed, "unmatched '}'");
      return false;
    }
    if (pattern[i] != '{') continue;
    const auto close = pattern.find('}', i);
    if (close == std::string::npos) {
      c.error(field, json_quote(pattern), allowed, "unmatched '{'");
      return false;
    }
    const std::string name = pattern.substr(i, close - i + 1);
    if (std::find(placeholders.begin(), placeholders.end(), name) == placeholders.end()) {
      c.error(field, json_quote(pattern), allowed, "unknown placeholder " + name + (did_you_mean(name, placeholders).empty() ? "" : "; " + did_you_mean(name, placeholders)));
      return false;
    }
    i = close;
  }
  return true;
}

// ---------------------------------------------------------------------------------------
// Sections

const std::vector<std::string> kSourceTypes = {"png16", "raw_f32", "esri_ascii", "procedural"};
const std::vector<std::string> kProceduralKinds = {"flat", "plane", "hills", "noise"};
const std::vector<std::string> kShapeKinds = {"sphere", "box", "cylinder", "capsule", "mesh"};
const std::vector<std::string> kBackends = {"cpu", "gl"};
const std::vector<std::string> kHeightfieldFormats = {"png16", "raw_f32", "esri_ascii"};

// Value limits, one place (docs/scene-format.md lists the same).
const Range kWorldCoord = closed(-1e9, 1e9, "m");
const Range kSize = positive(1e4, "m");

TerrainDef parse_terrain(Ctx& c, const json& j) {
  TerrainDef t;
  Obj o(c, j, "terrain");
  if (const json* src = o.require("source", "an object with \"type\": " + join(kSourceTypes, " | "))) {
    Obj s(c, *src, o.at("source"));
    auto& d = t.source;
    if (s.enumeration_req("type", d.kind, kSourceTypes) && s.valid()) {
      if (d.kind == TerrainSourceKind::Procedural) {
        auto& p = d.procedural;
        s.enumeration("kind", p.kind, kProceduralKinds);
        s.number("height", p.height, closed(-1e5, 1e5, "m"));
        s.number("slope_x", p.slope_x, closed(-100.0, 100.0, "m/m"));
        s.number("slope_z", p.slope_z, closed(-100.0, 100.0, "m/m"));
        s.number("amplitude", p.amplitude, closed(0.0, 1e5, "m"));
        s.number("wavelength", p.wavelength, positive(1e7, "m"));
        if (const json* v = s.get("seed")) {
          if (auto x = read_integer(c, *v, s.at("seed"), 0, 4294967295.0)) p.seed = static_cast<std::uint64_t>(*x);
        }
        s.integer("octaves", p.octaves, 1, 16);
        s.integer("samples_x", p.samples_x, 2, 65536);
        s.integer("samples_z", p.samples_z, 2, 65536);
      } else {
        std::string written;
        const bool raw = d.kind == TerrainSourceKind::RawF32;
        bool dims = true;
        if (raw) {
          dims = s.integer_req("samples_x", d.samples_x, 2, 65536) & s.integer_req("samples_z", d.samples_z, 2, 65536);
        }
        if (s.string_req("file", written, "the heightmap's path")) {
          d.file = resolve(c, written);
          const std::string field = s.at("file");
          if (check_readable(c, field, written, d.file, "heightmap")) {
            if (d.kind == TerrainSourceKind::Png16) check_png16(c, field, written, d.file);
            if (raw && dims) check_raw_f32(c, field, written, d.file, d.samples_x, d.samples_z);
            if (d.kind == TerrainSourceKind::EsriAscii) check_esri_ascii(c, field, written, d.file);
          }
        }
      }
    }
    s.finish();
  }
  if (!o.both("spacing", "size")) {
    t.spacing_given = o.has("spacing");
    o.number("spacing", t.spacing, closed(1e-4, 1e4, "m"));
    if (const json* v = o.get("size")) {
      if (auto sz = read_numbers<2>(c, *v, o.at("size"), positive(1e7, "m"))) t.size = *sz;
    }
  }
  if (t.size && t.source.kind == TerrainSourceKind::Procedural) {
    // The grid has one spacing: size must give square cells for the generator's sample count.
    const auto& p = t.source.procedural;
    const auto sp = t.spacing_xz(p.samples_x, p.samples_z);
    if (std::abs(sp[0] - sp[1]) > 1e-9 * std::max(sp[0], sp[1])) {
      c.error(o.at("size"), show(*o.get("size")), "must give square cells: size[0] / (samples_x - 1) = size[1] / (samples_z - 1)",
              "spacing would be " + fmt_num(sp[0]) + " m in x and " + fmt_num(sp[1]) + " m in z");
    }
  }
  o.number("vertical_scale", t.vertical_scale, positive(1e5, "m"));
  o.number("vertical_offset", t.vertical_offset, closed(-1e6, 1e6, "m"));
  o.vec3("origin", t.origin, kWorldCoord);
  if (!o.both("soil_depth", "bedrock_height")) {
    t.soil_depth = o.number_opt("soil_depth", positive(1e4, "m"));
    t.bedrock_height = o.number_opt("bedrock_height", closed(-1e6, 1e6, "m"));
  }
  if (!t.soil_depth && !t.bedrock_height && !o.has("soil_depth") && !o.has("bedrock_height")) t.soil_depth = knobs::kSoilDepth.def;
  // patch_depth: given, at most the soil depth; left out, the default or the soil depth if less.
  if (o.has("patch_depth")) {
    o.knob("patch_depth", t.patch_depth, knobs::kPatchDepth);
    if (t.soil_depth && t.patch_depth > *t.soil_depth)
      c.error(o.at("patch_depth"), fmt_num(t.patch_depth), "must be at most terrain.soil_depth (" + fmt_num(*t.soil_depth) + " m)");
  } else if (t.soil_depth) {
    t.patch_depth = std::min(t.patch_depth, *t.soil_depth);
  }
  o.string("material", t.material);
  o.finish();
  return t;
}

MaterialDef parse_material(Ctx& c, const json& j, const std::string& path) {
  MaterialDef m;
  Obj o(c, j, path);
  o.string_req("name", m.name, "a unique name");
  o.knob("density", m.density, knobs::kDensity);
  o.knob("friction", m.friction, knobs::kFriction);
  if (!o.both("restitution", "damping_ratio")) {
    const bool given = o.has("restitution") || o.has("damping_ratio");
    m.restitution = o.number_opt("restitution", {knobs::kRestitution.lo, knobs::kRestitution.hi, knobs::kRestitution.lo_open,
                                                 knobs::kRestitution.hi_open, knobs::kRestitution.unit});
    m.damping_ratio = o.number_opt("damping_ratio", {0.0, 100.0, false, false, ""});
    if (!given && o.valid()) c.missing(o.at("restitution"), "one of 'restitution' (e in (0, 1]) or 'damping_ratio' (ζ in [0, 100])");
  }
  o.knob("stiffness", m.stiffness, knobs::kStiffness);
  o.knob("tangential_stiffness_ratio", m.tangential_stiffness_ratio, knobs::kTangentialRatio);
  o.knob("granule_radius", m.granule_radius, knobs::kGranuleRadius);
  o.number("packing_fraction", m.packing_fraction, {0.0, 0.74, true, false, ""});
  o.finish();
  return m;
}

// Quaternion [w, x, y, z] from extrinsic x-y-z Euler angles in degrees: R = Rz(γ)·Ry(β)·Rx(α).
std::array<double, 4> euler_deg_to_quaternion(const Vec3d& e) {
  const double d = kPi / 180.0;
  const Eigen::Quaterniond q = Eigen::AngleAxisd(e[2] * d, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(e[1] * d, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(e[0] * d, Eigen::Vector3d::UnitX());
  return {q.w(), q.x(), q.y(), q.z()};
}

// The mesh of a body's shape if it loads (errors added to `c` otherwise).
std::optional<TriangleMesh> load_body_mesh(Ctx& c, ShapeDef& s, const std::string& field, const std::string& written) {
  auto r = load_obj_mesh(s.file, s.scale);
  if (!r) {
    for (const auto& e : r.errors()) {
      c.error(field, json_quote(written), e.allowed.empty() ? "must be a readable Wavefront OBJ file" : "must be " + e.allowed,
              e.file + ": " + e.detail);
    }
    return std::nullopt;
  }
  if (s.solid) {
    const auto errs = check_solid_mesh(*r, s.file, field);
    for (const auto& e : errs) c.error(field, json_quote(written), "must be " + e.allowed + " for a solid body", e.file + ": " + e.detail);
    if (!errs.empty()) return std::nullopt;
    s.mesh_volume = r->signed_volume();
  }
  return std::move(r).value();
}

double lowest_offset(const BodyDef& b, const TriangleMesh* mesh);

BodyDef parse_body(Ctx& c, const json& j, const std::string& path, std::optional<TriangleMesh>& mesh) {
  BodyDef b;
  Obj o(c, j, path);
  o.string_req("name", b.name, "a unique name");
  if (const json* sj = o.require("shape", "an object with \"type\": " + join(kShapeKinds, " | "))) {
    Obj s(c, *sj, o.at("shape"));
    auto& sh = b.shape;
    if (s.enumeration_req("type", sh.kind, kShapeKinds) && s.valid()) {
      switch (sh.kind) {
        case ShapeKind::Sphere: s.number_req("radius", sh.radius, kSize); break;
        case ShapeKind::Box: s.vec3_req("half_extents", sh.half_extents, kSize); break;
        case ShapeKind::Cylinder:
          s.number_req("radius", sh.radius, kSize);
          s.number_req("height", sh.height, kSize);
          break;
        case ShapeKind::Capsule:
          s.number_req("radius", sh.radius, kSize);
          s.number_req("height", sh.height, closed(0.0, 1e4, "m"));
          break;
        case ShapeKind::Mesh: {
          bool scale_ok = true;
          if (const json* v = s.get("scale")) {
            const auto x = read_number(c, *v, s.at("scale"), closed(1e-6, 1e6, "m per OBJ unit"));
            if (x) sh.scale = *x;
            scale_ok = x.has_value();
          }
          s.boolean("solid", sh.solid);
          std::string written;
          if (s.string_req("file", written, "the OBJ file's path")) {
            sh.file = resolve(c, written);
            if (check_readable(c, s.at("file"), written, sh.file, "OBJ file") && scale_ok) {
              mesh = load_body_mesh(c, sh, s.at("file"), written);
            }
          }
          break;
        }
      }
    }
    s.finish();
  }
  if (!o.both("mass", "density")) {
    const bool given = o.has("mass") || o.has("density");
    b.mass = o.number_opt("mass", positive(1e9, "kg"));
    b.density = o.number_opt("density", positive(1e5, "kg/m^3"));
    if (!given && o.valid()) c.missing(o.at("mass"), "one of 'mass' (kg) or 'density' (kg/m^3)");
    if (o.has("density") && b.shape.kind == ShapeKind::Mesh && !b.shape.solid) {
      c.error(o.at("density"), show(*o.get("density")), "give 'mass' for a mesh with \"solid\": false",
              "an open surface has no volume");
    }
  }
  if (const json* pj = o.get("pose")) {
    Obj p(c, *pj, o.at("pose"));
    p.vec3("position", b.pose.position, kWorldCoord);
    if (!p.both("orientation", "euler_deg")) {
      if (const json* q = p.get("orientation")) {
        if (auto v = read_numbers<4>(c, *q, p.at("orientation"), closed(-1.0 - 1e-3, 1.0 + 1e-3, ""))) {
          const double n = std::sqrt((*v)[0] * (*v)[0] + (*v)[1] * (*v)[1] + (*v)[2] * (*v)[2] + (*v)[3] * (*v)[3]);
          if (std::abs(n - 1.0) > 1e-3) {
            c.error(p.at("orientation"), show(*q), "must be a unit quaternion [w, x, y, z] (|q| = 1 ± 0.001)",
                    "|q| = " + fmt_num(n));
          } else {
            b.pose.orientation = {(*v)[0] / n, (*v)[1] / n, (*v)[2] / n, (*v)[3] / n};
          }
        }
      }
      if (const json* e = p.get("euler_deg")) {
        if (auto v = read_numbers<3>(c, *e, p.at("euler_deg"), closed(-720.0, 720.0, "deg"))) {
          b.pose.orientation = euler_deg_to_quaternion(*v);
        }
      }
    }
    p.finish();
  }
  o.vec3("linear_velocity", b.linear_velocity, closed(-1e3, 1e3, "m/s"));
  o.vec3("angular_velocity", b.angular_velocity, closed(-1e4, 1e4, "rad/s"));
  o.number("spawn_time", b.spawn_time, closed(0.0, 1e6, "s"));
  o.knob("friction", b.friction, knobs::kBodyFriction);
  o.knob("restitution", b.restitution, knobs::kBodyRestitution);
  o.knob("rolling_friction", b.rolling_friction, knobs::kBodyRollingFriction);
  o.finish();
  return b;
}

SceneSimulationDef parse_simulation(Ctx& c, const json& j) {
  SceneSimulationDef s;
  Obj o(c, j, "simulation");
  // A preset first: the fields below override it.
  if (const json* pj = o.get("preset")) {
    std::vector<std::string> names;
    for (const auto& p : simulation_presets()) names.push_back(p.name);
    if (auto x = read_enum(c, *pj, o.at("preset"), names)) {
      const SimulationPreset& p = simulation_presets()[std::size_t(*x)];
      s.preset = p.name;
      s.particle_scale = p.particle_scale;
      s.pool.granules_per_slot = p.granules_per_slot;
      s.steps_per_contact = p.steps_per_contact;
    }
  }
  o.number("dt", s.dt, {0.0, 0.1, true, false, "s"});
  o.integer("substeps", s.substeps, 1, 1000);
  o.number("duration", s.duration, positive(1e6, "s"));
  o.enumeration("backend", s.backend, kBackends);
  o.knob("threads", s.threads, knobs::kThreads);
  if (const json* pj = o.get("pool")) {
    Obj p(c, *pj, o.at("pool"));
    p.knob("slots", s.pool.slots, knobs::kSlots);
    p.knob("granules_per_slot", s.pool.granules_per_slot, knobs::kGranulesPerSlot);
    p.finish();
  }
  o.knob("particle_scale", s.particle_scale, knobs::kParticleScale);
  o.knob("steps_per_contact", s.steps_per_contact, knobs::kStepsPerContact);
  o.knob("max_substeps", s.max_substeps, knobs::kMaxSubsteps);
  if (const json* lj = o.get("lod")) {
    Obj p(c, *lj, o.at("lod"));
    p.knob("horizon", s.lod.horizon, knobs::kLodHorizon);
    p.knob("margin", s.lod.margin, knobs::kLodMargin);
    p.knob("apron", s.lod.apron, knobs::kLodApron);
    p.finish();
  }
  if (const json* bj = o.get("scale_by_distance")) {
    Obj p(c, *bj, o.at("scale_by_distance"));
    ScaleByDistanceDef d;
    p.string_req("camera", d.camera, "the name of a camera in cameras");
    if (const json* arr = p.require("bands", "an array of 1 to 16 objects {\"max_distance\", \"particle_scale\"}")) {
      if (arr->is_array() && (arr->empty() || arr->size() > 16)) {
        c.error(p.at("bands"), show(*arr), "must hold 1 to 16 bands", "got " + std::to_string(arr->size()));
      } else {
        for_each_element(c, *arr, p.at("bands"), [&](const json& e, const std::string& path) {
          ScaleBandDef band;
          Obj bo(c, e, path);
          const bool ok = bo.number_req("max_distance", band.max_distance, positive(1e7, "m"));
          bo.number_req("particle_scale", band.particle_scale, closed(1e-3, 1e3, ""));
          bo.finish();
          if (ok && !d.bands.empty() && band.max_distance <= d.bands.back().max_distance)
            c.error(bo.at("max_distance"), fmt_num(band.max_distance), "must be greater than the previous band's",
                    "follows " + fmt_num(d.bands.back().max_distance) + " m");
          d.bands.push_back(band);
        });
      }
    }
    p.finish();
    s.scale_by_distance = d;
  }
  if (const json* sj = o.get("sleep")) {
    Obj p(c, *sj, o.at("sleep"));
    p.knob("speed_threshold", s.sleep.speed_threshold, knobs::kSleepSpeed);
    p.knob("hold_time", s.sleep.hold_time, knobs::kSleepTime);
    p.finish();
  }
  o.knob("idle_timeout", s.idle_timeout, knobs::kIdleTimeout);
  o.boolean("granular_patches", s.granular_patches);
  o.vec3("gravity", s.gravity, closed(-1e3, 1e3, "m/s^2"));
  o.u64("seed", s.seed);
  o.finish();
  return s;
}

CameraDef parse_camera(Ctx& c, const json& j, const std::string& path) {
  CameraDef cam;
  Obj o(c, j, path);
  o.string_req("name", cam.name, "a unique name");
  const auto check_view = [&](const Vec3d& pos, const Vec3d& tgt, const std::string& field, const json& v) {
    if (pos == tgt) c.error(field, show(v), "must differ from the position", "the camera has no view direction");
  };
  if (const json* pj = o.get("path")) {
    if (o.has("position") || o.has("target")) {
      c.error(o.at("path"), show(*pj), "give either 'path' or 'position' and 'target'", "both are given");
    }
    for_each_element(c, *pj, o.at("path"), [&](const json& e, const std::string& p) {
      CameraKeyDef k;
      Obj ko(c, e, p);
      const bool t_ok = ko.number_req("time", k.time, closed(0.0, 1e6, "s"));
      const bool v_ok = ko.vec3_req("position", k.position, kWorldCoord) & ko.vec3_req("target", k.target, kWorldCoord);
      ko.finish();
      if (t_ok && !cam.path.empty() && k.time <= cam.path.back().time) {
        c.error(ko.at("time"), show(e["time"]), "keyframe times must be strictly ascending",
                "follows " + fmt_num(cam.path.back().time));
      }
      if (v_ok) check_view(k.position, k.target, ko.at("target"), e["target"]);
      cam.path.push_back(k);
    });
    if (pj->is_array() && pj->empty()) c.error(o.at("path"), show(*pj), "must hold at least one keyframe");
  } else {
    const bool ok = o.vec3_req("position", cam.position, kWorldCoord) & o.vec3_req("target", cam.target, kWorldCoord);
    if (ok) check_view(cam.position, cam.target, o.at("target"), *o.get("target"));
  }
  o.number("fov_deg", cam.fov_deg, closed(1.0, 179.0, "deg"));
  o.integer("width", cam.width, 16, 16384, "px");
  o.integer("height", cam.height, 16, 16384, "px");
  o.finish();
  return cam;
}

OutputsDef parse_outputs(Ctx& c, const json& j) {
  OutputsDef out;
  Obj o(c, j, "outputs");
  if (const json* fj = o.get("frames")) {
    for_each_element(c, *fj, o.at("frames"), [&](const json& e, const std::string& p) {
      FrameOutputDef f;
      Obj fo(c, e, p);
      fo.string_req("camera", f.camera, "the name of a camera");
      if (!fo.both("times", "every_k_frames")) {
        if (const json* t = fo.get("times")) f.times = read_times(c, *t, fo.at("times"));
        fo.integer("every_k_frames", f.every_k_frames, 1, 1e6);
        if (!fo.has("times") && !fo.has("every_k_frames") && fo.valid()) {
          c.missing(fo.at("times"), "one of 'times' (s) or 'every_k_frames'");
        }
      }
      fo.string("file", f.file);
      valid_pattern(c, fo.at("file"), f.file, {"{camera}", "{frame}", "{time_ms}"});
      fo.finish();
      out.frames.push_back(std::move(f));
    });
  }
  if (const json* hj = o.get("heightfields")) {
    for_each_element(c, *hj, o.at("heightfields"), [&](const json& e, const std::string& p) {
      HeightfieldOutputDef h;
      Obj ho(c, e, p);
      ho.enumeration("format", h.format, kHeightfieldFormats);
      if (const json* t = ho.get("times")) h.times = read_times(c, *t, ho.at("times"));
      ho.boolean("at_end", h.at_end);
      if (h.times.empty() && !h.at_end && ho.valid() && !ho.has("times")) {
        c.missing(ho.at("times"), "'times' (s) and/or \"at_end\": true");
      }
      ho.string("file", h.file);
      valid_pattern(c, ho.at("file"), h.file, {"{frame}", "{time_ms}", "{ext}"});
      ho.finish();
      out.heightfields.push_back(std::move(h));
    });
  }
  o.boolean("report", out.report);
  o.finish();
  return out;
}

template <class T>
void check_unique_names(Ctx& c, const std::vector<T>& items, const std::string& section) {
  std::map<std::string, std::size_t> seen;
  for (std::size_t i = 0; i < items.size(); ++i) {
    if (items[i].name.empty()) continue;
    const auto [it, inserted] = seen.emplace(items[i].name, i);
    if (!inserted) {
      c.error(section + "[" + std::to_string(i) + "].name", json_quote(items[i].name), "names must be unique",
              "the same as " + section + "[" + std::to_string(it->second) + "].name");
    }
  }
}

template <class T>
std::vector<std::string> names_of(const std::vector<T>& items) {
  std::vector<std::string> n;
  for (const auto& i : items) n.push_back(i.name);
  return n;
}

std::array<double, 9> rotation_rows(const std::array<double, 4>& q) {
  const Eigen::Matrix3d r = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
  return {r(0, 0), r(0, 1), r(0, 2), r(1, 0), r(1, 1), r(1, 2), r(2, 0), r(2, 1), r(2, 2)};
}

// Distance (m, ≥ 0) from the body's position down to its lowest point.
double lowest_offset(const BodyDef& b, const TriangleMesh* mesh) {
  const auto r = rotation_rows(b.pose.orientation);
  const double r10 = r[3], r11 = r[4], r12 = r[5];  // world y row
  const auto& s = b.shape;
  switch (s.kind) {
    case ShapeKind::Sphere: return s.radius;
    case ShapeKind::Box:
      return std::abs(r10) * s.half_extents[0] + std::abs(r11) * s.half_extents[1] + std::abs(r12) * s.half_extents[2];
    case ShapeKind::Cylinder:  // axis = body y; the rim's extent is radius·sin(tilt)
      return std::abs(r11) * s.height / 2 + s.radius * std::sqrt(std::max(0.0, 1.0 - r11 * r11));
    case ShapeKind::Capsule: return std::abs(r11) * s.height / 2 + s.radius;
    case ShapeKind::Mesh: {
      if (!mesh) return 0.0;
      double lowest = 0.0;
      for (const auto& v : mesh->vertices) lowest = std::min(lowest, r10 * v.x() + r11 * v.y() + r12 * v.z());
      return -lowest;
    }
  }
  return 0.0;
}

void check_flat_bedrock(Ctx& c, const SceneDef& s, const std::vector<std::optional<TriangleMesh>>& meshes) {
  if (!s.terrain.bedrock_height) return;
  const double bedrock = s.terrain.origin[1] + *s.terrain.bedrock_height;
  for (std::size_t i = 0; i < s.bodies.size(); ++i) {
    const auto& b = s.bodies[i];
    if (b.shape.kind == ShapeKind::Mesh && !meshes[i]) continue;
    const double low = b.pose.position[1] - lowest_offset(b, meshes[i] ? &*meshes[i] : nullptr);
    if (low < bedrock) {
      c.error("bodies[" + std::to_string(i) + "].pose.position", json(b.pose.position).dump(),
              "the body's lowest point must start at or above the bedrock (world y = " + fmt_num(bedrock) +
                  " m: terrain.origin[1] + terrain.bedrock_height)",
              "body below bedrock: its lowest point is at y = " + fmt_num(low) + " m");
    }
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Public API

std::array<double, 2> TerrainDef::spacing_xz(int nx, int nz) const {
  if (size) return {(*size)[0] / std::max(1, nx - 1), (*size)[1] / std::max(1, nz - 1)};
  return {spacing, spacing};
}

// e and ζ are related through the contact law the DEM integrates, the linear dashpot that
// never pulls (particles/material.hpp; docs/dem.md "Restitution").
double MaterialDef::damping_ratio_value() const {
  if (damping_ratio) return *damping_ratio;
  return damping_ratio_from_restitution(restitution.value_or(1.0));
}

double MaterialDef::restitution_value() const {
  if (restitution) return *restitution;
  return clamped_restitution(damping_ratio.value_or(0.0));
}

double ShapeDef::volume() const {
  switch (kind) {
    case ShapeKind::Sphere: return 4.0 / 3.0 * kPi * radius * radius * radius;
    case ShapeKind::Box: return 8.0 * half_extents[0] * half_extents[1] * half_extents[2];
    case ShapeKind::Cylinder: return kPi * radius * radius * height;
    case ShapeKind::Capsule: return kPi * radius * radius * height + 4.0 / 3.0 * kPi * radius * radius * radius;
    case ShapeKind::Mesh: return mesh_volume;
  }
  return 0.0;
}

double BodyDef::mass_value() const { return mass ? *mass : density.value_or(0.0) * shape.volume(); }

const MaterialDef* SceneDef::find_material(const std::string& n) const {
  for (const auto& m : materials) {
    if (m.name == n) return &m;
  }
  return nullptr;
}

const CameraDef* SceneDef::find_camera(const std::string& n) const {
  for (const auto& cam : cameras) {
    if (cam.name == n) return &cam;
  }
  return nullptr;
}

const char* to_string(TerrainSourceKind k) { return kSourceTypes[static_cast<int>(k)].c_str(); }
const char* to_string(ProceduralKind k) { return kProceduralKinds[static_cast<int>(k)].c_str(); }
const char* to_string(ShapeKind k) { return kShapeKinds[static_cast<int>(k)].c_str(); }
const std::vector<SimulationPreset>& simulation_presets() {
  // Chosen from the Pareto front of `sandpatch bench tradeoff` (docs/tradeoff.md has the table).
  static const std::vector<SimulationPreset> presets = {
      // crater_s2_n10_p6: depth 6-10 % from the reference (t_c/50, scale 1) at 1/26-1/33 of its
      // cost; N = 10 at 0.65-0.7 of N = 20's cost, within the crater's seed scatter of it;
      // piles of <= 100 granules flatten (angle 55-77 % low)
      {"game", 2.0, 4096, 10, "crater_s2_n10_p6_cpu"},
      // crater_s1.5_n10_p6: 1/10-1/19 of the reference's cost; N = 10 and 20 within the crater's
      // seed scatter of each other (two runs disagree on the order); pile 30-45 % low (s = 1.26)
      {"balanced", 1.5, 10240, 10, "crater_s1.5_n10_p6_cpu"},
      // crater_s1_n20_p6: depth within 0.5-4 % of t_c/50; pile within its seed-to-seed scatter and
      // at rest after its relaxation (at N = 10 it still crept)
      {"engineering", 1.0, 32768, 20, "crater_s1_n20_p6_cpu, pile_s1_n20"},
  };
  return presets;
}

const SimulationPreset* find_simulation_preset(const std::string& name) {
  for (const auto& p : simulation_presets())
    if (name == p.name) return &p;
  return nullptr;
}

const char* to_string(Backend b) { return kBackends[static_cast<int>(b)].c_str(); }
const char* to_string(HeightfieldFormat f) { return kHeightfieldFormats[static_cast<int>(f)].c_str(); }

Result<SceneDef> parse_scene(const std::string& json_text, const std::string& source_name,
                             const std::string& base_dir) {
  ParsedText parsed = parse_json_text(json_text, source_name);
  if (parsed.error) return *parsed.error;
  const json& root = parsed.root;

  Ctx c;
  c.file = source_name;
  c.base_dir = base_dir.empty() ? fs::path(".") : fs::path(base_dir);
  for (const auto& p : parsed.duplicate_keys) {
    c.error(p, "", "each key may appear once per object", "duplicate key");
  }

  SceneDef s;
  s.source_path = source_name;
  s.name = fs::path(source_name).stem().string();
  Obj top(c, root, "");
  if (const json* v = top.get("version")) {
    read_integer(c, *v, "version", kSceneFormatVersion, kSceneFormatVersion);
  }
  top.string("name", s.name);
  top.string("description", s.description, /*non_empty=*/false);
  if (const json* mj = top.require("materials", "an array of at least one material")) {
    for_each_element(c, *mj, "materials", [&](const json& e, const std::string& p) {
      s.materials.push_back(parse_material(c, e, p));
    });
    if (mj->is_array() && mj->empty()) c.error("materials", "[]", "must hold at least one material");
  }
  if (const json* tj = top.require("terrain", "an object with a \"source\"")) s.terrain = parse_terrain(c, *tj);
  std::vector<std::optional<TriangleMesh>> meshes;
  if (const json* bj = top.get("bodies")) {
    for_each_element(c, *bj, "bodies", [&](const json& e, const std::string& p) {
      std::optional<TriangleMesh> mesh;
      s.bodies.push_back(parse_body(c, e, p, mesh));
      meshes.push_back(std::move(mesh));
    });
  }
  if (const json* sj = top.get("simulation")) s.simulation = parse_simulation(c, *sj);
  if (const json* cj = top.get("cameras")) {
    for_each_element(c, *cj, "cameras", [&](const json& e, const std::string& p) {
      s.cameras.push_back(parse_camera(c, e, p));
    });
  }
  if (const json* oj = top.get("outputs")) s.outputs = parse_outputs(c, *oj);
  top.finish();

  // Cross references.
  check_unique_names(c, s.materials, "materials");
  check_unique_names(c, s.bodies, "bodies");
  check_unique_names(c, s.cameras, "cameras");
  if (s.terrain.material.empty()) {
    if (!s.materials.empty()) s.terrain.material = s.materials.front().name;
  } else if (!s.find_material(s.terrain.material) && !s.materials.empty()) {
    const auto names = names_of(s.materials);
    c.error("terrain.material", json_quote(s.terrain.material), "must name a material: " + join(names),
            did_you_mean(s.terrain.material, names));
  }
  for (std::size_t i = 0; i < s.outputs.frames.size(); ++i) {
    const auto& cam = s.outputs.frames[i].camera;
    if (!cam.empty() && !s.find_camera(cam)) {
      const auto names = names_of(s.cameras);
      c.error("outputs.frames[" + std::to_string(i) + "].camera", json_quote(cam),
              names.empty() ? "must name a camera (the scene has none)" : "must name a camera: " + join(names),
              did_you_mean(cam, names));
    }
  }
  if (const auto& sd = s.simulation.scale_by_distance; sd && !sd->camera.empty() && !s.find_camera(sd->camera)) {
    const auto names = names_of(s.cameras);
    c.error("simulation.scale_by_distance.camera", json_quote(sd->camera),
            names.empty() ? "must name a camera (the scene has none)" : "must name a camera: " + join(names),
            did_you_mean(sd->camera, names));
  }
  check_flat_bedrock(c, s, meshes);

  if (!c.errors.empty()) return std::move(c.errors);

  // Hash: canonical JSON (keys sorted, no whitespace) + the bytes of every referenced file.
  Hasher h;
  h.str(root.dump());
  for (const auto& f : c.referenced_files) {
    std::ifstream in(f, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    h.str(f.substr(f.find_last_of('/') + 1));
    h.str(bytes.str());
  }
  s.hash = h.hex();
  return s;
}

Result<SceneDef> load_scene_file(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return Error{path, "", "", "must be an existing scene file", "file not found"};
  if (!fs::is_regular_file(path, ec)) return Error{path, "", "", "must be an existing scene file", "not a regular file"};
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path, "", "", "must be a readable scene file", "file cannot be opened"};
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return Error{path, "", "", "must be a readable scene file", "read failed"};
  std::string base = fs::path(path).parent_path().string();
  return parse_scene(text.str(), path, base.empty() ? "." : base);
}

namespace {
#include "scene/default_scene.inc"  // const char kDefaultSceneJson[] = R"(...)": scenes/default.json
}  // namespace

const char* default_scene_json() { return kDefaultSceneJson; }

Result<SceneDef> load_default_scene() { return parse_scene(default_scene_json(), "<embedded default>", ""); }

nlohmann::json scene_to_json(const SceneDef& s) {
  json j;
  j["version"] = kSceneFormatVersion;
  j["name"] = s.name;
  j["description"] = s.description;

  json t;
  json src;
  src["type"] = to_string(s.terrain.source.kind);
  if (s.terrain.source.kind == TerrainSourceKind::Procedural) {
    const auto& p = s.terrain.source.procedural;
    src["kind"] = to_string(p.kind);
    src["height"] = p.height;
    src["slope_x"] = p.slope_x;
    src["slope_z"] = p.slope_z;
    src["amplitude"] = p.amplitude;
    src["wavelength"] = p.wavelength;
    src["seed"] = p.seed;
    src["octaves"] = p.octaves;
    src["samples_x"] = p.samples_x;
    src["samples_z"] = p.samples_z;
  } else {
    src["file"] = s.terrain.source.file;
    if (s.terrain.source.kind == TerrainSourceKind::RawF32) {
      src["samples_x"] = s.terrain.source.samples_x;
      src["samples_z"] = s.terrain.source.samples_z;
    }
  }
  t["source"] = src;
  if (s.terrain.size) t["size"] = *s.terrain.size;
  else t["spacing"] = s.terrain.spacing;
  t["vertical_scale"] = s.terrain.vertical_scale;
  t["vertical_offset"] = s.terrain.vertical_offset;
  t["origin"] = s.terrain.origin;
  if (s.terrain.bedrock_height) t["bedrock_height"] = *s.terrain.bedrock_height;
  else t["soil_depth"] = s.terrain.soil_depth.value_or(knobs::kSoilDepth.def);
  t["patch_depth"] = s.terrain.patch_depth;
  t["material"] = s.terrain.material;
  j["terrain"] = t;

  j["materials"] = json::array();
  for (const auto& m : s.materials) {
    json mj;
    mj["name"] = m.name;
    mj["density"] = m.density;
    mj["friction"] = m.friction;
    if (m.damping_ratio) mj["damping_ratio"] = *m.damping_ratio;
    else mj["restitution"] = m.restitution_value();
    mj["stiffness"] = m.stiffness;
    mj["tangential_stiffness_ratio"] = m.tangential_stiffness_ratio;
    mj["granule_radius"] = m.granule_radius;
    mj["packing_fraction"] = m.packing_fraction;
    j["materials"].push_back(mj);
  }

  j["bodies"] = json::array();
  for (const auto& b : s.bodies) {
    json bj, sh;
    bj["name"] = b.name;
    sh["type"] = to_string(b.shape.kind);
    switch (b.shape.kind) {
      case ShapeKind::Sphere: sh["radius"] = b.shape.radius; break;
      case ShapeKind::Box: sh["half_extents"] = b.shape.half_extents; break;
      case ShapeKind::Cylinder:
      case ShapeKind::Capsule:
        sh["radius"] = b.shape.radius;
        sh["height"] = b.shape.height;
        break;
      case ShapeKind::Mesh:
        sh["file"] = b.shape.file;
        sh["scale"] = b.shape.scale;
        sh["solid"] = b.shape.solid;
        break;
    }
    bj["shape"] = sh;
    if (b.density) bj["density"] = *b.density;
    else bj["mass"] = b.mass.value_or(0.0);
    bj["pose"] = {{"position", b.pose.position}, {"orientation", b.pose.orientation}};
    bj["linear_velocity"] = b.linear_velocity;
    bj["angular_velocity"] = b.angular_velocity;
    bj["spawn_time"] = b.spawn_time;
    bj["friction"] = b.friction;
    bj["restitution"] = b.restitution;
    bj["rolling_friction"] = b.rolling_friction;
    j["bodies"].push_back(bj);
  }

  const auto& sim = s.simulation;
  j["simulation"] = {
      {"dt", sim.dt},
      {"substeps", sim.substeps},
      {"duration", sim.duration},
      {"backend", to_string(sim.backend)},
      {"threads", sim.threads},
      {"pool", {{"slots", sim.pool.slots}, {"granules_per_slot", sim.pool.granules_per_slot}}},
      {"particle_scale", sim.particle_scale},
      {"steps_per_contact", sim.steps_per_contact},
      {"max_substeps", sim.max_substeps},
      {"lod", {{"horizon", sim.lod.horizon}, {"margin", sim.lod.margin}, {"apron", sim.lod.apron}}},
      {"sleep", {{"speed_threshold", sim.sleep.speed_threshold}, {"hold_time", sim.sleep.hold_time}}},
      {"idle_timeout", sim.idle_timeout},
      {"granular_patches", sim.granular_patches},
      {"gravity", sim.gravity},
      {"seed", sim.seed},
  };
  // Only when one was applied (every field above already holds its values), so scenes without
  // a preset keep their canonical JSON and hash.
  if (!sim.preset.empty()) j["simulation"]["preset"] = sim.preset;
  if (sim.scale_by_distance) {
    json bands = json::array();
    for (const auto& b : sim.scale_by_distance->bands)
      bands.push_back({{"max_distance", b.max_distance}, {"particle_scale", b.particle_scale}});
    j["simulation"]["scale_by_distance"] = {{"camera", sim.scale_by_distance->camera}, {"bands", bands}};
  }

  j["cameras"] = json::array();
  for (const auto& cam : s.cameras) {
    json cj;
    cj["name"] = cam.name;
    if (cam.path.empty()) {
      cj["position"] = cam.position;
      cj["target"] = cam.target;
    } else {
      cj["path"] = json::array();
      for (const auto& k : cam.path) {
        cj["path"].push_back({{"time", k.time}, {"position", k.position}, {"target", k.target}});
      }
    }
    cj["fov_deg"] = cam.fov_deg;
    cj["width"] = cam.width;
    cj["height"] = cam.height;
    j["cameras"].push_back(cj);
  }

  json out;
  out["frames"] = json::array();
  for (const auto& f : s.outputs.frames) {
    json fj{{"camera", f.camera}, {"file", f.file}};
    if (f.every_k_frames > 0) fj["every_k_frames"] = f.every_k_frames;
    else fj["times"] = f.times;
    out["frames"].push_back(fj);
  }
  out["heightfields"] = json::array();
  for (const auto& h : s.outputs.heightfields) {
    json hj{{"format", to_string(h.format)}, {"at_end", h.at_end}, {"file", h.file}};
    if (!h.times.empty()) hj["times"] = h.times;
    out["heightfields"].push_back(hj);
  }
  out["report"] = s.outputs.report;
  j["outputs"] = out;
  return j;
}

double body_extent_below(const BodyDef& body) {
  if (body.shape.kind != ShapeKind::Mesh) return lowest_offset(body, nullptr);
  auto mesh = load_obj_mesh(body.shape.file, body.shape.scale);
  return mesh ? lowest_offset(body, &*mesh) : 0.0;
}

std::vector<Error> check_bodies_against_terrain(
    const SceneDef& scene, const std::function<float(double x, double z)>& bedrock_world_height) {
  std::vector<Error> errors;
  for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
    const auto& b = scene.bodies[i];
    const double x = b.pose.position[0], z = b.pose.position[2];
    const double bedrock = bedrock_world_height(x, z);
    const double low = b.pose.position[1] - body_extent_below(b);
    if (low < bedrock) {
      errors.push_back({scene.source_path, "bodies[" + std::to_string(i) + "].pose.position",
                        json(b.pose.position).dump(),
                        "the body's lowest point must start at or above the bedrock (world y = " + fmt_num(bedrock) +
                            " m under x = " + fmt_num(x) + ", z = " + fmt_num(z) + ")",
                        "body below bedrock: its lowest point is at y = " + fmt_num(low) + " m"});
    }
  }
  return errors;
}

}  // namespace sandpatch
