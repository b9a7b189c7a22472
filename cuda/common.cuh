// Shared definitions of the kernels: the portability macros, a small 3-vector over the scalar
// type T (double, or float for mixed-precision pair geometry), and the math wrappers.
//
// Every header in this folder compiles three ways:
// - with NVRTC at run time (`__CUDACC_RTC__`), the production path (src/backend/cuda);
// - with nvcc (`__CUDACC__`), for anyone building the kernels offline;
// - as plain host C++17 (g++/clang++), so that the geometry can be tested against the Rust
//   implementation on a machine without a GPU (tests/cuda_geometry_host.rs).
// Functions are therefore `PD_HD` (host and device), use no dynamic allocation, no recursion
// and no standard library beyond <cmath>/<cstdint> on the host.
//
// Floating-point contraction is off in all three builds (NVRTC `--fmad=false`, g++
// `-ffp-contract=off`): the Rust reference never fuses a multiply and an add, and parity in
// double mode is then limited only by the transcendental functions (cbrt, sin, cos).
#pragma once

#if defined(__CUDACC_RTC__) || defined(__CUDACC__)
#define PD_HD __host__ __device__ __forceinline__
#define PD_DEVICE __device__ __forceinline__
// A rarely taken branch kept out of line: inlined, its loops bloat the hot kernel it sits in
// (the contained-body test cost the settled mineral grains 30 % of their speed, docs/performance.md).
#define PD_HD_COLD __host__ __device__ __noinline__
typedef unsigned long long pd_u64;
typedef long long pd_i64;
typedef unsigned int pd_u32;
#else
#include <cmath>
#include <cstdint>
#include <cstring>
#define PD_HD inline
#define PD_DEVICE inline
#define PD_HD_COLD inline
typedef uint64_t pd_u64;
typedef int64_t pd_i64;
typedef uint32_t pd_u32;
#endif

// Doubles per contact in the contact history: the tangential spring (3), the current loading
// cycle's approach speed signed by its phase, the twist angle (Rust:
// backend::cuda::layout::HISTORY_WIDTH).
#define PD_HISTORY_WIDTH 5

// The contact flag of a pair or a particle–wall slot in contact, whose spring is live history
// (Rust: backend::cuda::layout::CONTACT_LIVE).
#define PD_CONTACT_LIVE 1u

// No slot: a particle that had none on this rank before a decomposed run's rebuild.
#define PD_NO_SLOT 0xffffffffu

namespace pd {

// Math wrappers with one overload per precision: the device math library's C++ overloads and
// <cmath>'s differ in which float overloads they declare, so everything goes through these.
PD_HD double sqrt_(double x) { return sqrt(x); }
PD_HD float sqrt_(float x) { return sqrtf(x); }
PD_HD double abs_(double x) { return fabs(x); }
PD_HD float abs_(float x) { return fabsf(x); }
PD_HD double min_(double a, double b) { return a < b ? a : b; }
PD_HD float min_(float a, float b) { return a < b ? a : b; }
PD_HD double max_(double a, double b) { return a > b ? a : b; }
PD_HD float max_(float a, float b) { return a > b ? a : b; }
PD_HD double cbrt_(double x) { return cbrt(x); }
PD_HD float cbrt_(float x) { return cbrtf(x); }
PD_HD int min_(int a, int b) { return a < b ? a : b; }

// The bits of a double and back (Rust's f64::to_bits / from_bits).
PD_HD pd_u64 double_bits(double x) {
#if defined(__CUDACC_RTC__) || defined(__CUDACC__)
    return (pd_u64)__double_as_longlong(x);
#else
    pd_u64 b;
    std::memcpy(&b, &x, sizeof b);
    return b;
#endif
}
PD_HD double bits_double(pd_u64 b) {
#if defined(__CUDACC_RTC__) || defined(__CUDACC__)
    return __longlong_as_double((long long)b);
#else
    double x;
    std::memcpy(&x, &b, sizeof x);
    return x;
#endif
}

// The cube root from + − × ÷ and bit operations only (Rust geometry::real::portable_cbrt, whose
// docs give the method): the CPU and the GPU round it identically, where libm's cbrt and CUDA's
// differ in the last bit for some arguments.
PD_HD double portable_cbrt(double x) {
    double sign = 1.0;
    if (x < 0.0) {
        x = -x;
        sign = -1.0;
    }
    if (x == 0.0 || !(x - x == 0.0)) return sign * x;
    pd_u64 bits = double_bits(x);
    pd_i64 adjust = 0;
    if ((bits >> 52) == 0) {
        bits = double_bits(x * 18014398509481984.0); // 2^54
        adjust = -18;
    }
    pd_i64 e = (pd_i64)((bits >> 52) & 0x7ff) - 1023;
    pd_i64 k = e >= 0 ? e / 3 : -((2 - e) / 3);
    pd_i64 r = e - 3 * k;
    double m = bits_double((bits & 0x000fffffffffffffULL) | (((pd_u64)(1023 + r)) << 52));
    double y = 0.5 + 0.25 * m;
    for (int i = 0; i < 6; ++i) y -= (y * y * y - m) / (3.0 * y * y);
    return sign * bits_double((pd_u64)((pd_i64)double_bits(y) + (k + adjust) * ((pd_i64)1 << 52)));
}
// ln 2 in two parts (Rust geometry::real::LN2_HI / LN2_LO).
#define PD_LN2_HI 6.931471803691238e-1
#define PD_LN2_LO 1.9082149292705877e-10

// The natural logarithm from + − × ÷ and bit operations only (Rust geometry::real::portable_ln,
// whose docs give the method): NaN for x <= 0 or non-finite x.
PD_HD double portable_ln(double x) {
    if (!(x > 0.0 && x - x == 0.0)) return bits_double(0x7ff8000000000000ULL); // NaN
    pd_u64 bits = double_bits(x);
    pd_i64 e = 0;
    if ((bits >> 52) == 0) {
        bits = double_bits(x * 18014398509481984.0); // 2^54
        e = -54;
    }
    e += (pd_i64)((bits >> 52) & 0x7ff) - 1023;
    double m = bits_double((bits & 0x000fffffffffffffULL) | (((pd_u64)1023) << 52));
    if (m > 1.4142135623730951) { // SQRT_2
        m *= 0.5;
        e += 1;
    }
    double f = (m - 1.0) / (m + 1.0);
    double z = f * f;
    double series = 1.0 / 21.0;
    for (int k = 9; k >= 0; --k) series = 1.0 / (double)(2 * k + 1) + z * series;
    double ed = (double)e;
    return ed * PD_LN2_HI + (2.0 * f * series + ed * PD_LN2_LO);
}

// e^y from + − × ÷, floor and bit operations only (Rust geometry::real::portable_exp).
PD_HD double portable_exp(double y) {
    if (y != y) return y;
    if (y > 710.0) return bits_double(0x7ff0000000000000ULL); // infinity
    if (y < -746.0) return 0.0;
    double n = floor(y * 1.4426950408889634 + 0.5); // LOG2_E
    double r = (y - n * PD_LN2_HI) - n * PD_LN2_LO;
    double p = 1.0 / 87178291200.0; // 1/14!
    double fact = 87178291200.0;
    for (int k = 13; k >= 0; --k) {
        fact /= (double)(k + 1);
        p = 1.0 / fact + r * p;
    }
    pd_i64 ni = (pd_i64)n;
    pd_i64 half = ni / 2;
    double a = bits_double(((pd_u64)(1023 + half)) << 52);
    double b = bits_double(((pd_u64)(1023 + (ni - half))) << 52);
    return p * a * b;
}

// x^p for x >= 0 as exp(p ln x) (Rust geometry::real::portable_pow): 0 for x = 0, p > 0.
PD_HD double portable_pow(double x, double p) {
    if (x == 0.0 && p > 0.0) return 0.0;
    return portable_exp(p * portable_ln(x));
}

PD_HD int max_(int a, int b) { return a > b ? a : b; }

// sin and cos from + − × ÷ and floor only (Rust geometry::real::portable_sin_cos, whose docs
// give the method): libm's and CUDA's sin/cos differ in the last bit for some arguments, and
// the free rotation takes five of them per particle and step.
PD_HD void portable_sin_cos(double x, double* s_out, double* c_out) {
    if (!(x - x == 0.0)) {
        *s_out = x - x;
        *c_out = x - x;
        return;
    }
    const double pio2_hi = 1.5707963267341256;   // 0x1.921fb544p+0, 33 significant bits
    const double pio2_lo = 6.077100506506192e-11; // pi/2 - pio2_hi
    const double sin_coeffs[8] = {-1.0 / 6.0,           1.0 / 120.0,          -1.0 / 5040.0,
                                  1.0 / 362880.0,       -1.0 / 39916800.0,    1.0 / 6227020800.0,
                                  -1.0 / 1307674368000.0, 1.0 / 355687428096000.0};
    const double cos_coeffs[8] = {1.0 / 24.0,           -1.0 / 720.0,           1.0 / 40320.0,
                                  -1.0 / 3628800.0,     1.0 / 479001600.0,      -1.0 / 87178291200.0,
                                  1.0 / 20922789888000.0, -1.0 / 6402373705728000.0};
    double n = 0.0, r = x;
    if (!(abs_(x) <= 0.78539816339744830962)) { // FRAC_PI_4
        n = floor(x * 0.63661977236758134308 + 0.5); // FRAC_2_PI
        r = (x - n * pio2_hi) - n * pio2_lo;
    }
    double z = r * r;
    double ps = sin_coeffs[7], pc = cos_coeffs[7];
    for (int k = 6; k >= 0; --k) {
        ps = sin_coeffs[k] + z * ps;
        pc = cos_coeffs[k] + z * pc;
    }
    double s = r + r * z * ps;
    double c = 1.0 - (0.5 * z - z * z * pc);
    double quadrant = n - 4.0 * floor(n * 0.25);
    if (quadrant == 0.0) {
        *s_out = s;
        *c_out = c;
    } else if (quadrant == 1.0) {
        *s_out = c;
        *c_out = -s;
    } else if (quadrant == 2.0) {
        *s_out = -s;
        *c_out = -c;
    } else {
        *s_out = -c;
        *c_out = s;
    }
}

// Machine epsilon and the largest finite value of T (Rust's f64::EPSILON / f32::EPSILON).
template <class T> struct Limits;
template <> struct Limits<double> {
    static PD_HD double epsilon() { return 2.220446049250313080847e-16; }
    static PD_HD double max() { return 1.7976931348623157e308; }
};
template <> struct Limits<float> {
    static PD_HD float epsilon() { return 1.1920928955078125e-7f; }
    static PD_HD float max() { return 3.40282346638528859812e38f; }
};

// A 3-vector. Operations are written component by component in the order nalgebra uses
// (x, then y, then z; dot = x*x' + y*y' + z*z' summed left to right), so that double results
// match the Rust reference bit for bit where no transcendental function intervenes.
template <class T> struct V3 {
    T x, y, z;
    PD_HD T operator[](int k) const { return k == 0 ? x : (k == 1 ? y : z); }
};

template <class T> PD_HD V3<T> v3(T x, T y, T z) {
    V3<T> v;
    v.x = x;
    v.y = y;
    v.z = z;
    return v;
}
template <class T> PD_HD V3<T> zero3() { return v3<T>(T(0), T(0), T(0)); }
template <class T> PD_HD V3<T> operator+(V3<T> a, V3<T> b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
template <class T> PD_HD V3<T> operator-(V3<T> a, V3<T> b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
template <class T> PD_HD V3<T> operator-(V3<T> a) { return v3(-a.x, -a.y, -a.z); }
template <class T> PD_HD V3<T> operator*(V3<T> a, T s) { return v3(a.x * s, a.y * s, a.z * s); }
template <class T> PD_HD V3<T> operator/(V3<T> a, T s) { return v3(a.x / s, a.y / s, a.z / s); }
template <class T> PD_HD V3<T>& operator+=(V3<T>& a, V3<T> b) {
    a = a + b;
    return a;
}
template <class T> PD_HD V3<T>& operator-=(V3<T>& a, V3<T> b) {
    a = a - b;
    return a;
}
template <class T> PD_HD bool operator==(V3<T> a, V3<T> b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
template <class T> PD_HD T dot(V3<T> a, V3<T> b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
template <class T> PD_HD V3<T> cross(V3<T> a, V3<T> b) {
    return v3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
template <class T> PD_HD T norm2(V3<T> a) { return dot(a, a); }
template <class T> PD_HD T norm(V3<T> a) { return sqrt_(norm2(a)); }
template <class T> PD_HD V3<T> vmin(V3<T> a, V3<T> b) { return v3(min_(a.x, b.x), min_(a.y, b.y), min_(a.z, b.z)); }
template <class T> PD_HD V3<T> vmax(V3<T> a, V3<T> b) { return v3(max_(a.x, b.x), max_(a.y, b.y), max_(a.z, b.z)); }
template <class T> PD_HD T vmax_component(V3<T> a) { return max_(max_(a.x, a.y), a.z); }

// Precision conversions: the pair frame is built in double and rounded to T once (docs/design.md §3).
template <class T, class S> PD_HD V3<T> cast3(V3<S> a) { return v3<T>(T(a.x), T(a.y), T(a.z)); }

// A unit quaternion (w; x, y, z), body → world, as nalgebra's UnitQuaternion.
template <class T> struct Quat {
    T w, x, y, z;
};

// Rotates v by q: nalgebra's `UnitQuaternion * Vector3`, in its order of operations
// (t = 2 q×v; v' = (t w + q×t) + v).
template <class T> PD_HD V3<T> rotate(Quat<T> q, V3<T> v) {
    V3<T> u = v3(q.x, q.y, q.z);
    V3<T> t = cross(u, v) * T(2);
    return t * q.w + cross(u, t) + v;
}

// Rotates v by q⁻¹ (world → body).
template <class T> PD_HD V3<T> rotate_inverse(Quat<T> q, V3<T> v) {
    Quat<T> c;
    c.w = q.w;
    c.x = -q.x;
    c.y = -q.y;
    c.z = -q.z;
    return rotate(c, v);
}

// A 3×3 matrix, row-major (m[r][c]); only what the pair frame needs.
template <class T> struct Mat3 {
    T m[3][3];
};

// nalgebra's `UnitQuaternion::to_rotation_matrix`, in its order of operations
// (ij = i·j·2 etc., diagonal ww + ii − jj − kk summed left to right).
template <class T> PD_HD Mat3<T> to_rotation_matrix(Quat<T> q) {
    T i = q.x, j = q.y, k = q.z, w = q.w;
    T ww = w * w, ii = i * i, jj = j * j, kk = k * k;
    T ij = i * j * T(2), wk = w * k * T(2), wj = w * j * T(2);
    T ik = i * k * T(2), jk = j * k * T(2), wi = w * i * T(2);
    Mat3<T> r;
    r.m[0][0] = ww + ii - jj - kk;
    r.m[0][1] = ij - wk;
    r.m[0][2] = wj + ik;
    r.m[1][0] = wk + ij;
    r.m[1][1] = ww - ii + jj - kk;
    r.m[1][2] = jk - wi;
    r.m[2][0] = ik - wj;
    r.m[2][1] = wi + jk;
    r.m[2][2] = ww - ii - jj + kk;
    return r;
}

// Matrix × vector as nalgebra's gemv: column by column, so row r is
// (m[r][0] x + m[r][1] y) + m[r][2] z.
template <class T> PD_HD V3<T> mul(const Mat3<T>& a, V3<T> v) {
    return v3(a.m[0][0] * v.x + a.m[0][1] * v.y + a.m[0][2] * v.z,
              a.m[1][0] * v.x + a.m[1][1] * v.y + a.m[1][2] * v.z,
              a.m[2][0] * v.x + a.m[2][1] * v.y + a.m[2][2] * v.z);
}

} // namespace pd
