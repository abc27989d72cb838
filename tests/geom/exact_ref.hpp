// SPDX-License-Identifier: BSD-3-Clause
// Test-only exact reference for the predicates and the triangle test, independent of the code
// under test: integers of fixed capacity, every double converted exactly (x = M·2^e, M odd) to
// an integer at a common power-of-two scale, and overlap decided as "origin in the convex hull
// of the nine vertex differences" by brute force over Carathéodory subsets. No floating point.
#pragma once
#include <Eigen/Core>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <vector>

namespace st::test {

/// Signed integer with up to 32·kLimbs bits; throws on overflow (a test bug, never silent).
class BigInt {
 public:
  static constexpr int kLimbs = 120;
  BigInt() = default;
  BigInt(std::int64_t v) {  // NOLINT: implicit from integers, like the built-ins
    neg_ = v < 0;
    std::uint64_t m = neg_ ? ~static_cast<std::uint64_t>(v) + 1 : static_cast<std::uint64_t>(v);
    while (m != 0) {
      d_[n_++] = static_cast<std::uint32_t>(m);
      m >>= 32;
    }
  }
  /// this · 2^bits
  BigInt shifted(int bits) const {
    BigInt r;
    if (n_ == 0) return r;
    const int limbs = bits / 32, rem = bits % 32;
    if (n_ + limbs + 1 > kLimbs) throw std::overflow_error("BigInt shift overflow");
    std::uint32_t carry = 0;
    for (int i = 0; i < n_; ++i) {
      const std::uint64_t v = static_cast<std::uint64_t>(d_[i]) << rem;
      r.d_[i + limbs] = static_cast<std::uint32_t>(v) | carry;
      carry = static_cast<std::uint32_t>(v >> 32);
    }
    r.n_ = n_ + limbs;
    if (carry != 0) r.d_[r.n_++] = carry;
    r.neg_ = neg_;
    return r;
  }
  int sign() const { return n_ == 0 ? 0 : (neg_ ? -1 : 1); }
  BigInt operator-() const {
    BigInt r = *this;
    if (r.n_ != 0) r.neg_ = !r.neg_;
    return r;
  }
  friend BigInt operator+(const BigInt& a, const BigInt& b) {
    if (a.neg_ == b.neg_) {
      BigInt r = add_mag(a, b);
      r.neg_ = a.neg_ && r.n_ != 0;
      return r;
    }
    const int c = cmp_mag(a, b);
    if (c == 0) return BigInt();
    BigInt r = c > 0 ? sub_mag(a, b) : sub_mag(b, a);
    r.neg_ = c > 0 ? a.neg_ : b.neg_;
    return r;
  }
  friend BigInt operator-(const BigInt& a, const BigInt& b) { return a + (-b); }
  friend BigInt operator*(const BigInt& a, const BigInt& b) {
    BigInt r;
    if (a.n_ == 0 || b.n_ == 0) return r;
    if (a.n_ + b.n_ > kLimbs) throw std::overflow_error("BigInt multiply overflow");
    std::uint64_t acc[kLimbs] = {};
    for (int i = 0; i < a.n_; ++i) {
      std::uint64_t carry = 0;
      for (int j = 0; j < b.n_; ++j) {
        const std::uint64_t t = static_cast<std::uint64_t>(a.d_[i]) * b.d_[j] + acc[i + j] + carry;
        acc[i + j] = t & 0xffffffffu;
        carry = t >> 32;
      }
      acc[i + b.n_] += carry;
    }
    r.n_ = a.n_ + b.n_;
    for (int i = 0; i < r.n_; ++i) r.d_[i] = static_cast<std::uint32_t>(acc[i]);
    r.trim();
    r.neg_ = a.neg_ != b.neg_;
    return r;
  }
  friend bool operator==(const BigInt& a, const BigInt& b) { return (a - b).sign() == 0; }

 private:
  static int cmp_mag(const BigInt& a, const BigInt& b) {
    if (a.n_ != b.n_) return a.n_ < b.n_ ? -1 : 1;
    for (int i = a.n_ - 1; i >= 0; --i)
      if (a.d_[i] != b.d_[i]) return a.d_[i] < b.d_[i] ? -1 : 1;
    return 0;
  }
  static BigInt add_mag(const BigInt& a, const BigInt& b) {
    BigInt r;
    const int n = std::max(a.n_, b.n_);
    if (n + 1 > kLimbs) throw std::overflow_error("BigInt add overflow");
    std::uint64_t carry = 0;
    for (int i = 0; i < n; ++i) {
      const std::uint64_t t = static_cast<std::uint64_t>(i < a.n_ ? a.d_[i] : 0) + (i < b.n_ ? b.d_[i] : 0) + carry;
      r.d_[i] = static_cast<std::uint32_t>(t);
      carry = t >> 32;
    }
    r.n_ = n;
    if (carry != 0) r.d_[r.n_++] = static_cast<std::uint32_t>(carry);
    return r;
  }
  static BigInt sub_mag(const BigInt& a, const BigInt& b) {  // |a| ≥ |b|
    BigInt r;
    std::int64_t borrow = 0;
    for (int i = 0; i < a.n_; ++i) {
      std::int64_t t = static_cast<std::int64_t>(a.d_[i]) - (i < b.n_ ? b.d_[i] : 0) - borrow;
      borrow = t < 0;
      if (t < 0) t += std::int64_t{1} << 32;
      r.d_[i] = static_cast<std::uint32_t>(t);
    }
    r.n_ = a.n_;
    r.trim();
    return r;
  }
  void trim() {
    while (n_ > 0 && d_[n_ - 1] == 0) --n_;
  }
  std::uint32_t d_[kLimbs] = {};
  int n_ = 0;
  bool neg_ = false;
};

inline int sgn(std::int64_t v) { return (v > 0) - (v < 0); }
inline int sgn(const BigInt& v) { return v.sign(); }

/// Exact integers m_i with x_i = m_i · 2^E for one common E (the lowest set bit among all x_i).
inline std::vector<BigInt> to_integers(const std::vector<double>& xs) {
  struct Split {
    std::int64_t m;
    int e;  // x = m·2^e, m odd (or 0)
  };
  std::vector<Split> s;
  int lowest = 1 << 20;
  for (double x : xs) {
    if (!std::isfinite(x)) throw std::invalid_argument("non-finite coordinate in reference");
    if (x == 0.0) {
      s.push_back({0, 0});
      continue;
    }
    int e;
    const double f = std::frexp(x, &e);  // x = f·2^e, 0.5 ≤ |f| < 1 (also for subnormals)
    auto m = static_cast<std::int64_t>(std::ldexp(f, 53));
    e -= 53;
    while ((m & 1) == 0) {
      m /= 2;
      ++e;
    }
    s.push_back({m, e});
    lowest = std::min(lowest, e);
  }
  std::vector<BigInt> out;
  for (const Split& v : s) out.push_back(v.m == 0 ? BigInt() : BigInt(v.m).shifted(v.e - lowest));
  return out;
}

template <class T>
using V3 = std::array<T, 3>;

template <class T>
V3<T> sub(const V3<T>& a, const V3<T>& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
template <class T>
V3<T> cross(const V3<T>& a, const V3<T>& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
template <class T>
T dot(const V3<T>& a, const V3<T>& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}
template <class T>
bool is_zero(const V3<T>& a) {
  return sgn(a[0]) == 0 && sgn(a[1]) == 0 && sgn(a[2]) == 0;
}
/// Sign of det[b−a; c−a; d−a] = ((b−a)×(c−a))·(d−a).
template <class T>
int orient(const V3<T>& a, const V3<T>& b, const V3<T>& c, const V3<T>& d) {
  return sgn(dot(cross(sub(b, a), sub(c, a)), sub(d, a)));
}

/// The origin lies in the convex hull of d. By Carathéodory it then lies in the hull of an
/// affinely independent subset of at most 4 points; every such subset is tried.
template <class T>
bool origin_in_hull(const std::vector<V3<T>>& d) {
  const int n = static_cast<int>(d.size());
  const V3<T> o{T(0), T(0), T(0)};
  for (int i = 0; i < n; ++i)
    if (is_zero(d[i])) return true;
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      if (is_zero(sub(d[i], d[j]))) continue;
      if (is_zero(cross(d[i], d[j])) && sgn(dot(d[i], d[j])) <= 0) return true;
    }
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      for (int k = j + 1; k < n; ++k) {
        const V3<T> nrm = cross(sub(d[j], d[i]), sub(d[k], d[i]));
        if (is_zero(nrm) || sgn(dot(nrm, d[i])) != 0) continue;
        const int idx[4] = {i, j, k, i};
        bool inside = true;
        for (int e = 0; e < 3 && inside; ++e) {
          const V3<T>& u = d[idx[e]];
          const V3<T>& w = d[idx[e + 1]];
          inside = sgn(dot(cross(sub(w, u), sub(o, u)), nrm)) >= 0;
        }
        if (inside) return true;
      }
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      for (int k = j + 1; k < n; ++k)
        for (int l = k + 1; l < n; ++l) {
          const int v = orient(d[i], d[j], d[k], d[l]);
          if (v == 0) continue;
          const int b0 = orient(o, d[j], d[k], d[l]), b1 = orient(d[i], o, d[k], d[l]),
                    b2 = orient(d[i], d[j], o, d[l]), b3 = orient(d[i], d[j], d[k], o);
          if (b0 * v >= 0 && b1 * v >= 0 && b2 * v >= 0 && b3 * v >= 0) return true;
        }
  return false;
}

/// Closed triangles (possibly degenerate) a and b intersect: 0 ∈ a − b = conv{a_i − b_j}.
template <class T>
bool ref_overlap(const std::array<V3<T>, 3>& a, const std::array<V3<T>, 3>& b) {
  std::vector<V3<T>> d;
  for (const auto& p : a)
    for (const auto& q : b) d.push_back(sub(p, q));
  return origin_in_hull(d);
}

using Vec3d = Eigen::Vector3d;

/// Exact reference on double vertices (converted exactly to BigInt at a common scale).
inline bool ref_overlap_doubles(const std::array<Vec3d, 3>& a, const std::array<Vec3d, 3>& b) {
  std::vector<double> xs;
  for (const auto* t : {&a, &b})
    for (const Vec3d& v : *t)
      for (int k = 0; k < 3; ++k) xs.push_back(v[k]);
  const std::vector<BigInt> m = to_integers(xs);
  std::array<V3<BigInt>, 3> ia, ib;
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      ia[i][k] = m[3 * i + k];
      ib[i][k] = m[9 + 3 * i + k];
    }
  return ref_overlap(ia, ib);
}

/// Exact sign of orient3d on doubles.
inline int ref_orient3d(const Vec3d& a, const Vec3d& b, const Vec3d& c, const Vec3d& d) {
  std::vector<double> xs;
  for (const Vec3d* p : {&a, &b, &c, &d})
    for (int k = 0; k < 3; ++k) xs.push_back((*p)[k]);
  const std::vector<BigInt> m = to_integers(xs);
  V3<BigInt> v[4];
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k) v[i][k] = m[3 * i + k];
  return orient(v[0], v[1], v[2], v[3]);
}

/// Exact sign of orient2d on doubles.
inline int ref_orient2d(double ax, double ay, double bx, double by, double cx, double cy) {
  const std::vector<BigInt> m = to_integers({ax, ay, bx, by, cx, cy});
  return sgn((m[2] - m[0]) * (m[5] - m[1]) - (m[3] - m[1]) * (m[4] - m[0]));
}

}  // namespace st::test
