// Reading a JSON scene file: the text parsed with nlohmann's SAX parser (duplicate keys and
// overflowing numbers kept as errors), then readers that check type, range and presence and
// remember which keys each object was asked for (the rest are unknown keys, with a "did you
// mean"), appending every problem to one error list; and the checks of referenced files'
// headers. Used by scene/scene.cpp; internal to the scene library.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/error.hpp"
#include "common/knobs.hpp"
#include "common/limits.hpp"

namespace sandpatch::scene_json {

namespace fs = std::filesystem;
using json = nlohmann::json;

inline constexpr double kPi = 3.14159265358979323846;
// Prefix of the string that stands in for a number too large for a double.
inline constexpr const char* kOverflowMarker = "\x01sandpatch-overflow:";

// ---------------------------------------------------------------------------------------
// Small text helpers

inline std::string fmt_num(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", x);
  return buf;
}

inline std::string json_quote(const std::string& s) { return json(s).dump(); }

inline std::string lower(std::string s) {
  for (auto& ch : s) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return s;
}

// Optimal string alignment distance (Damerau–Levenshtein without repeated edits of a
// substring): insertions, deletions, substitutions and adjacent transpositions cost 1.
inline std::size_t edit_distance(const std::string& a, const std::string& b) {
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
inline std::string closest(const std::string& word, const std::vector<std::string>& candidates) {
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

inline std::string did_you_mean(const std::string& word, const std::vector<std::string>& candidates) {
  const std::string best = closest(word, candidates);
  return best.empty() ? std::string() : "did you mean '" + best + "'?";
}

inline std::string join(const std::vector<std::string>& v, const std::string& sep = ", ") {
  std::string s;
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? sep : "") + v[i];
  return s;
}

// 1-based line and column of the character at 0-based byte `index` of `text`.
inline std::pair<std::size_t, std::size_t> line_column(const std::string& text, std::size_t index) {
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

// Byte index of the first '[' or '{' that opens level max_depth + 1 (strings skipped), or npos.
// Run before the parser: nesting is what the DOM, its destructor and the readers recurse on,
// so ~70,000 levels would overflow the stack (limits::kMaxJsonDepth).
inline std::size_t too_deep_at(const std::string& text, int max_depth) {
  int depth = 0;
  bool in_string = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char ch = text[i];
    if (in_string) {
      if (ch == '\\') ++i;  // the escaped character cannot close the string
      else if (ch == '"') in_string = false;
    } else if (ch == '"') {
      in_string = true;
    } else if (ch == '[' || ch == '{') {
      if (++depth > max_depth) return i;
    } else if (ch == ']' || ch == '}') {
      --depth;
    }
  }
  return std::string::npos;
}

inline ParsedText parse_json_text(std::string text, const std::string& file) {
  ParsedText out;
  if (const std::size_t at = too_deep_at(text, limits::kMaxJsonDepth); at != std::string::npos) {
    const auto [line, col] = line_column(text, at);
    out.error = Error{file, "line " + std::to_string(line) + ", column " + std::to_string(col), "",
                      "arrays and objects may be nested at most " + std::to_string(limits::kMaxJsonDepth) + " deep",
                      "nesting level " + std::to_string(limits::kMaxJsonDepth + 1) + " starts here"};
    return out;
  }
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

inline bool is_overflow_marker(const json& v) {
  return v.is_string() && v.get_ref<const std::string&>().starts_with(kOverflowMarker);
}

// The value as the user wrote it (compact JSON, long values shortened).
inline std::string show(const json& v) {
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

inline Range closed(double lo, double hi, const char* unit) { return {lo, hi, false, false, unit}; }
inline Range positive(double hi, const char* unit) { return {0.0, hi, true, false, unit}; }

// World coordinates (positions, the terrain's origin).
inline const Range kWorldCoord = closed(-1e9, 1e9, "m");

// The range of a knob or limit of the table (common/knobs.hpp).
inline Range range_of(const knobs::Knob& k) { return {k.lo, k.hi, k.lo_open, k.hi_open, k.unit}; }

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

inline std::string type_detail(const json& v) { return std::string("got ") + (v.is_null() ? "null" : v.type_name()); }

inline std::optional<double> read_number(Ctx& c, const json& v, const std::string& f, const Range& r) {
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
inline std::optional<double> read_integer(Ctx& c, const json& v, const std::string& f, double lo, double hi,
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

inline std::optional<std::uint64_t> read_u64(Ctx& c, const json& v, const std::string& f) {
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

inline std::optional<std::string> read_string(Ctx& c, const json& v, const std::string& f, bool non_empty = true) {
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

inline std::optional<bool> read_bool(Ctx& c, const json& v, const std::string& f) {
  if (!v.is_boolean()) {
    c.error(f, show(v), "must be true or false", v.is_string() ? "got a string; write true or false without quotes"
                                                                 : type_detail(v));
    return std::nullopt;
  }
  return v.get<bool>();
}

// A fixed-length array of numbers, each checked against `r`.
template <std::size_t N>
inline std::optional<std::array<double, N>> read_numbers(Ctx& c, const json& v, const std::string& f, const Range& r) {
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
inline std::optional<int> read_enum(Ctx& c, const json& v, const std::string& f, const std::vector<std::string>& choices) {
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
    number(key, out, range_of(k));
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
inline bool for_each_element(Ctx& c, const json& v, const std::string& f, F&& each) {
  if (!v.is_array()) {
    c.error(f, show(v), "must be an array [ ... ]", type_detail(v));
    return false;
  }
  for (std::size_t i = 0; i < v.size(); ++i) each(v[i], f + "[" + std::to_string(i) + "]");
  return true;
}

// Times in seconds: ascending, each in the range of knobs::kOutputTime.
inline std::vector<double> read_times(Ctx& c, const json& v, const std::string& f) {
  std::vector<double> times;
  for_each_element(c, v, f, [&](const json& e, const std::string& p) {
    if (auto t = read_number(c, e, p, range_of(knobs::kOutputTime))) {
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

inline std::string resolve(const Ctx& c, const std::string& written) {
  fs::path p(written);
  if (p.is_relative()) p = c.base_dir / p;
  return p.lexically_normal().string();
}

// True when the file exists and opens; otherwise an error on `field`.
inline bool check_readable(Ctx& c, const std::string& field, const std::string& written, const std::string& resolved,
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

inline std::string read_head(const std::string& path, std::size_t n) {
  std::ifstream in(path, std::ios::binary);
  std::string s(n, '\0');
  in.read(s.data(), static_cast<std::streamsize>(n));
  s.resize(static_cast<std::size_t>(in.gcount()));
  return s;
}

// Cheap content checks that catch a wrong format before any loader runs.
inline void check_png16(Ctx& c, const std::string& field, const std::string& written, const std::string& path) {
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
  // IHDR width and height (big-endian, bytes 16..23): the grid cap, from the header alone.
  auto be32 = [&](std::size_t at) {
    std::uint32_t v = 0;
    for (std::size_t k = 0; k < 4; ++k) v = (v << 8) | static_cast<unsigned char>(h[at + k]);
    return v;
  };
  if (auto e = limits::check_grid_size(path, "width × height", be32(16), be32(20))) {
    c.error(field, json_quote(written), e->allowed, path + ": " + e->value + "; " + e->detail);
  }
}

inline void check_raw_f32(Ctx& c, const std::string& field, const std::string& written, const std::string& path, int nx,
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

inline void check_esri_ascii(Ctx& c, const std::string& field, const std::string& written, const std::string& path) {
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

inline bool valid_pattern(Ctx& c, const std::string& field, const std::string& pattern,
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

}  // namespace sandpatch::scene_json
