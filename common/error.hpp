// Errors for untrusted input (scene files, heightmaps, meshes, parameters).
//
// Two tiers: programmer mistakes are asserts; anything a user
// can get wrong comes back as an Error that names the file, the field path, the
// offending value and what is allowed. Creation functions return Result<T>.
#pragma once

#include <cassert>
#include <cstdio>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace sandpatch {

// A number as error messages show it: 9 significant digits (reads back as the same float).
inline std::string format_number(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

// Exit codes of the command-line program (README, docs/cli.md).
enum class ExitCode : int { Ok = 0, RuntimeFailure = 1, BadInput = 2 };

struct Error {
  std::string file;     // file the bad input came from ("" when none, e.g. a definition struct)
  std::string field;    // JSON-pointer-like path: "bodies[2].pose.position"
  std::string value;    // the offending value as the user wrote it
  std::string allowed;  // what would have been accepted
  std::string detail;   // optional extra sentence ("did you mean 'friction'?")

  // "scenes/x.json: bodies[2].mass = -1: must be > 0 (kg)"
  std::string message() const {
    std::string m;
    if (!file.empty()) m += file + ": ";
    if (!field.empty()) m += field;
    if (!value.empty()) m += (field.empty() ? "" : " = ") + value;
    if (!allowed.empty()) m += (m.empty() || m.ends_with(": ") ? "" : ": ") + allowed;
    if (!detail.empty()) m += (m.empty() ? "" : "; ") + detail;
    return m;
  }
};

// A value or the list of errors that prevented it (at least one).
template <class T>
class Result {
 public:
  Result(T value) : v_(std::move(value)) {}                      // NOLINT: implicit on purpose
  Result(Error e) : v_(std::vector<Error>{std::move(e)}) {}      // NOLINT
  Result(std::vector<Error> es) : v_(std::move(es)) { assert(!std::get<1>(v_).empty()); }  // NOLINT

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }
  T& value() & { assert(ok()); return std::get<0>(v_); }
  const T& value() const& { assert(ok()); return std::get<0>(v_); }
  T&& value() && { assert(ok()); return std::move(std::get<0>(v_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  const std::vector<Error>& errors() const { assert(!ok()); return std::get<1>(v_); }
  const Error& error() const { return errors().front(); }
  // All error messages, one a line.
  std::string message() const {
    std::string m;
    for (const auto& e : errors()) m += e.message() + "\n";
    return m;
  }

 private:
  std::variant<T, std::vector<Error>> v_;
};

// Result<void> equivalent.
struct Ok {};
using Status = Result<Ok>;

}  // namespace sandpatch
