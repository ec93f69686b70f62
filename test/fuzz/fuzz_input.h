#pragma once
// Structured values from a fuzzer's bytes, for the harnesses that build messages and configs field
// by field (docs/fuzzing.md). Reading past the end
// yields zeros, so every input, however short, is a complete message. A number is either the field's
// default, a value from a short list of edge cases (0, negative, NaN, +-inf, huge, tiny), a scaled
// default, or 8 raw bytes: the checks a parameter or message field meets are mostly about those.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace topo_planner {
namespace fuzz {

class FuzzInput {
 public:
  FuzzInput(const uint8_t* data, size_t size) : data_(data), size_(size) {}

  size_t remaining() const { return size_ - pos_; }

  uint8_t byte() { return pos_ < size_ ? data_[pos_++] : 0; }
  bool flag() { return byte() & 1; }

  template <typename T>
  T raw() {
    uint8_t b[sizeof(T)] = {};
    const size_t n = std::min(sizeof(T), remaining());
    if (n) std::memcpy(b, data_ + pos_, n);
    pos_ += n;
    T v;
    std::memcpy(&v, b, sizeof(T));
    return v;
  }

  /// A double around `def` (see the file comment).
  double number(double def) {
    const uint8_t sel = byte();
    switch (sel % 16) {
      case 6: return 0.0;
      case 7: return -def;
      case 8: return def * (1.0 + byte() / 16.0);
      case 9: return def / (1.0 + byte());
      case 10: return std::numeric_limits<double>::quiet_NaN();
      case 11: return std::numeric_limits<double>::infinity();
      case 12: return -std::numeric_limits<double>::infinity();
      case 13: return (sel & 0x10) ? 1e300 : -1e300;
      case 14: return (sel & 0x10) ? 1e-300 : 1e-9;
      case 15: return raw<double>();
      default: return def;
    }
  }

  /// An integer around `def`: the default, 0, -1, +-1 steps, the type's extremes or raw bytes.
  template <typename T>
  T integer(T def) {
    const uint8_t sel = byte();
    switch (sel % 12) {
      case 6: return T(0);
      case 7: return T(-1);
      case 8: return T(uint64_t(def) + byte() % 8);  // wraps, no signed overflow
      case 9: return std::numeric_limits<T>::max();
      case 10: return std::numeric_limits<T>::min();
      case 11: return raw<T>();
      default: return def;
    }
  }

  /// One of `choices`, or (selector 255) a short string of the input's bytes.
  std::string choice(const std::vector<std::string>& choices) {
    const uint8_t sel = byte();
    if (sel == 255 || choices.empty()) return text(byte() % 16);
    return choices[sel % choices.size()];
  }

  std::string text(size_t max_len) {
    const size_t n = std::min(max_len, remaining());
    std::string s(reinterpret_cast<const char*>(data_ + pos_), n);
    pos_ += n;
    return s;
  }

  /// The bytes not read yet.
  std::vector<uint8_t> rest() {
    std::vector<uint8_t> v(data_ + pos_, data_ + size_);
    pos_ = size_;
    return v;
  }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

/// The inverse of FuzzInput, for the seed generator (make_seeds.cpp): writes the bytes that make
/// FuzzInput read the given values.
class FuzzOutput {
 public:
  void byte(uint8_t b) { bytes_.push_back(b); }
  void flag(bool b) { byte(b ? 1 : 0); }
  template <typename T>
  void raw(T v) {
    uint8_t b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    bytes_.insert(bytes_.end(), b, b + sizeof(T));
  }
  void number(double v) {
    byte(15);
    raw(v);
  }
  template <typename T>
  void integer(T v) {
    byte(11);
    raw(v);
  }
  void choice(size_t index) { byte(uint8_t(index)); }
  void append(const std::vector<uint8_t>& v) { bytes_.insert(bytes_.end(), v.begin(), v.end()); }
  const std::vector<uint8_t>& bytes() const { return bytes_; }

 private:
  std::vector<uint8_t> bytes_;
};

/// A broken property of the code under test: report and abort, so that the fuzzer keeps the input
/// and the replay gtest fails (assert() is compiled out in Release).
#define TOPO_PLANNER_FUZZ_CHECK(cond)                                                                  \
  do {                                                                                                \
    if (!(cond)) {                                                                                    \
      std::fprintf(stderr, "%s:%d: fuzz property violated: %s\n", __FILE__, __LINE__, #cond);         \
      std::abort();                                                                                   \
    }                                                                                                 \
  } while (0)

}  // namespace fuzz
}  // namespace topo_planner
