// Range checks over a definition struct that name the field, its value and what is allowed.
// One checker serves the library's errors (sandpatch::api::Error) and the internal ones
// (sandpatch::Error): both are {file, field, value, allowed, detail}.
#pragma once

#include <cmath>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "common/knobs.hpp"

namespace sandpatch {

template <class E>
struct BasicChecker {
  std::string prefix;  // "TerrainDef." / "BodyDef."
  std::string detail;  // appended to every error (e.g. the body's name)
  std::vector<E> errs;

  void add(const std::string& field, const std::string& value, const std::string& allowed) {
    errs.push_back(E{"", prefix + field, value, allowed, detail});
  }
  // lo_open / hi_open: the bound itself is excluded. NaN and infinities always fail.
  void number(const std::string& field, double v, double lo, double hi, bool lo_open, bool hi_open, const char* unit) {
    const bool ok = std::isfinite(v) && (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
    if (ok) return;
    std::string allowed = std::string("must be in ") + (lo_open ? "(" : "[") + format_number(lo) + ", " +
                          format_number(hi) + (hi_open ? ")" : "]");
    if (*unit) allowed += std::string(" ") + unit;
    add(field, format_number(v), allowed);
  }
  void closed(const std::string& f, double v, double lo, double hi, const char* unit = "") {
    number(f, v, lo, hi, false, false, unit);
  }
  void positive(const std::string& f, double v, double hi, const char* unit = "") { number(f, v, 0.0, hi, true, false, unit); }
  // A setting of the knob table (common/knobs.hpp): its range; the field is the table's name.
  // `suffix` names an element of the field ("[1]" of half_extents).
  void knob(const knobs::Knob& k, double v, const std::string& suffix = "") {
    if (k.allows(v)) return;
    errs.push_back(E{"", k.api + suffix, format_number(v), "must be in " + knobs::describe_range(k), detail});
  }
  void integer(const std::string& field, long long v, long long lo, long long hi) {
    if (v < lo || v > hi) add(field, std::to_string(v), "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
  }
  template <class A>
  void finite(const std::string& field, const A& v, const char* unit) {
    for (auto x : v)
      if (!std::isfinite(double(x))) {
        std::string s = "[";
        for (std::size_t k = 0; k < v.size(); ++k) s += (k ? ", " : "") + format_number(double(v[k]));
        add(field, s + "]", std::string("must be finite (") + unit + ")");
        return;
      }
  }
};

}  // namespace sandpatch
