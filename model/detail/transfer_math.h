#pragma once
// Natural logarithm and exponential for the transfer function's power τ^E = exp(E·ln τ)
// (intensity.h), inline. The renderer evaluates one power per pixel of the fall-off band, and the
// calls into libm (the out-of-line entries and the wrappers that set errno) were about a quarter
// of such a pixel's instructions besides the distance. Both functions agree with glibc's to 1–2
// ulp (model/intensity_test.cpp checks it), so images in float do not change in practice.
//
// Method: table-driven reductions as in Tang (1989, 1990, ACM TOMS 15 and 16) and glibc, with
// the tables written out below (correctly rounded, generated with Python's decimal module):
//  - ln x = k·ln 2 + ln c + ln(m/c), x = 2^k·m with m in [√½, √2], c = j/128 the nearest
//    multiple of 1/128 (m − c is exact), ln(m/c) = 2·atanh(s), s = (m − c)/(m + c), |s| < 0.0028,
//    atanh(s) = s + s³/3 + s⁵/5 + s⁷/7 (truncation below 1e-19 relative);
//  - exp y = 2^(k/64)·exp(r), k = round(64·y / ln 2), r = y − k·ln 2/64 (ln 2 in two parts so
//    that k·ln2_hi is exact), |r| < 0.0055, exp(r) = Σ r^n/n! for n ≤ 5 (truncation 4e-17).
// Arguments outside the fast ranges (non-positive, subnormal, infinite or NaN for the log;
// |y| ≥ 700 for the exponential) go to libm.

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace flarekit::model::detail {

// ln 2 = kLn2Hi + kLn2Lo, kLn2Hi with 32 significant bits (fdlibm's split), so k·kLn2Hi is
// exact for |k| < 2^21.
inline constexpr double kLn2Hi = 6.93147180369123816490e-01;
inline constexpr double kLn2Lo = 1.90821492927058770002e-10;

// ln(j/128) for j = 90 … 181.
inline constexpr std::array<double, 92> kLnTable = {
    -0.3522205935893521, -0.34117075740276714, -0.33024168687057687, -0.3194307707663612,
    -0.3087354816496133, -0.29815337231907635, -0.2876820724517809, -0.27731928541623435,
    -0.26706278524904525, -0.2569104137850272, -0.24686007793152578, -0.2369097470783577,
    -0.22705745063534608, -0.2173012756899814, -0.2076393647782445, -0.1980699137620938,
    -0.18859116980755003, -0.179201429457711, -0.16989903679539747, -0.16068238169047347,
    -0.15154989812720093, -0.14250006260728304, -0.13353139262452263, -0.1246424452072766,
    -0.1158318155251217, -0.1070981355563671, -0.09844007281325252, -0.08985632912186105,
    -0.0813456394539524, -0.07290677080808779, -0.06453852113757118, -0.05623971832287608,
    -0.048009219186360606, -0.039845908547199674, -0.0317486983145803, -0.023716526617316044,
    -0.015748356968139168, -0.007843177461025893, 0.0, 0.007782140442054949, 0.015504186535965254,
    0.02316705928153438, 0.030771658666753687, 0.0383188643021366, 0.0458095360312942,
    0.053244514518812285, 0.06062462181643484, 0.06795066190850775, 0.07522342123758753,
    0.08244366921107459, 0.08961215868968714, 0.09672962645855111, 0.10379679368164356,
    0.11081436634029011, 0.11778303565638346, 0.12470347850095724, 0.13157635778871926,
    0.13840232285911913, 0.1451820098444979, 0.15191604202584197, 0.15860503017663857,
    0.16524957289530717, 0.17185025692665923, 0.1784076574728183, 0.184922338494012,
    0.19139485299962947, 0.19782574332991987, 0.2042155414286909, 0.21056476910734964,
    0.21687393830061436, 0.22314355131420976, 0.22937410106484582, 0.2355660713127669,
    0.24171993688714516, 0.24783616390458127, 0.25391520998096345, 0.25995752443692605,
    0.26596354849713794, 0.27193371548364176, 0.2778684510034563, 0.2837681731306446,
    0.28963329258304266, 0.2954642128938359, 0.3012613305781618, 0.3070250352949119,
    0.3127557100038969, 0.3184537311185346, 0.324119468654212, 0.329753286372468,
    0.3353555419211378, 0.3409265869705932, 0.34646676734620857};;

// 2^(j/64) for j = 0 … 63.
inline constexpr std::array<double, 64> kExp2Table = {
    1.0, 1.0108892860517005, 1.0218971486541166, 1.0330248790212284, 1.0442737824274138,
    1.0556451783605572, 1.0671404006768237, 1.0787607977571199, 1.0905077326652577,
    1.102382583307841, 1.1143867425958924, 1.1265216186082418, 1.1387886347566916,
    1.1511892299529827, 1.1637248587775775, 1.1763969916502812, 1.189207115002721,
    1.202156731452703, 1.215247359980469, 1.22848053610687, 1.241857812073484, 1.255380757024691,
    1.2690509571917332, 1.2828700160787783, 1.2968395546510096, 1.3109612115247644,
    1.3252366431597413, 1.339667524053303, 1.3542555469368927, 1.3690024229745905,
    1.383909881963832, 1.3989796725383112, 1.4142135623730951, 1.42961333839197,
    1.4451808069770467, 1.460917794180647, 1.4768261459394993, 1.4929077282912648,
    1.5091644275934228, 1.5255981507445384, 1.5422108254079407, 1.559004400237837,
    1.5759808451078865, 1.593142151342267, 1.6104903319492543, 1.6280274218573478,
    1.645755478153965, 1.6636765803267364, 1.681792830507429, 1.7001063537185235,
    1.718619298122478, 1.7373338352737062, 1.7562521603732995, 1.7753764925265212,
    1.7947090750031072, 1.8142521755003989, 1.8340080864093424, 1.8539791250833855,
    1.8741676341103, 1.8945759815869656, 1.9152065613971474, 1.9360617934922943,
    1.9571441241754002, 1.978456026387951};;

// The same arithmetic on one double or on four at once (GCC/Clang vector extension; the renderer
// evaluates the transfer function for a block's pixels together, intensity.h): each lane does
// the scalar operations in the same order, so every lane's result equals the scalar one bit for
// bit. The few operations without a common spelling are the overloads below. Always inlined: the
// vector forms are compiled into each instruction-set clone of their caller (a call between
// clones would pass the vectors differently), so GCC's note that passing 32-byte vectors without
// AVX differs from passing them with it (-Wpsabi) never applies. (Clang 14 rejects such calls in
// the plain x86-64 clone even when they are inlined: there, two-lane vectors would be the way.)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"
#endif
#define FLAREKIT_LANES_INLINE [[gnu::always_inline]] inline
typedef double Double4 __attribute__((vector_size(32)));
typedef std::int64_t Int64x4 __attribute__((vector_size(32)));
typedef std::int32_t Int32x4 __attribute__((vector_size(16)));

template <typename Real>
using IntFor = std::conditional_t<std::is_same_v<Real, double>, std::int64_t, Int64x4>;

// std::bit_cast, as the builtin: inlined in unoptimised builds too, where std::bit_cast is a call,
// and a call from the AVX2 clone into the plain x86-64 copy would return the vector elsewhere.
template <typename To, typename From>
FLAREKIT_LANES_INLINE To bitCast(const From& from) {
  return __builtin_bit_cast(To, from);
}
// The integer part of a value in [0, 2^31) (truncation, as a cast to int).
FLAREKIT_LANES_INLINE std::int64_t truncateToInt(double x) { return static_cast<int>(x); }
FLAREKIT_LANES_INLINE Int64x4 truncateToInt(Double4 x) {
  // double → int32 is one instruction per lane group (cvttpd2dq) on every x86-64; to int64 is not.
  return __builtin_convertvector(__builtin_convertvector(x, Int32x4), Int64x4);
}
// An integer below 2^51 in magnitude as a double (exact either way): 1.5·2^52 + k has k in its
// low mantissa bits, so the vector form is an integer add and a subtraction (AVX2 has no int64 →
// double conversion).
FLAREKIT_LANES_INLINE double toDouble(std::int64_t k) { return static_cast<double>(k); }
FLAREKIT_LANES_INLINE Double4 toDouble(Int64x4 k) {
  return bitCast<Double4>(k + 0x4338000000000000) - 6755399441055744.0;
}
// The integer value of a double that holds one below 2^51 in magnitude (exact).
FLAREKIT_LANES_INLINE std::int64_t roundedToInt(double x) { return static_cast<std::int64_t>(x); }
FLAREKIT_LANES_INLINE Int64x4 roundedToInt(Double4 x) {
  return bitCast<Int64x4>(x + 6755399441055744.0) - 0x4338000000000000;
}
// table[index] per lane.
template <std::size_t N>
FLAREKIT_LANES_INLINE double lookup(const std::array<double, N>& table, std::int64_t index) {
  return table[static_cast<std::size_t>(index)];
}
template <std::size_t N>
FLAREKIT_LANES_INLINE Double4 lookup(const std::array<double, N>& table, Int64x4 index) {
  return Double4{table[static_cast<std::size_t>(index[0])], table[static_cast<std::size_t>(index[1])],
                 table[static_cast<std::size_t>(index[2])], table[static_cast<std::size_t>(index[3])]};
}
// 1 where `condition` holds, else 0 (a vector comparison gives −1 per true lane).
FLAREKIT_LANES_INLINE std::int64_t oneIf(bool condition) { return condition; }
FLAREKIT_LANES_INLINE Int64x4 oneIf(Int64x4 condition) { return condition & 1; }

// ln x for normal, finite, positive x (the caller checks the range; transferLog below).
template <typename Real>
FLAREKIT_LANES_INLINE Real transferLogCore(Real x) {
  using Int = IntFor<Real>;
  const Int bits = bitCast<Int>(x);
  // m in [√½, √2] (ln x has no cancellation near x = 1): the mantissa in [1, 2), halved when above
  // √2 by taking one from its exponent (exact, the same bits as m·0.5). Written without a branch:
  // for τ spread over (0, 1) the test goes either way at random, and a mispredicted branch cost
  // more than the whole reduction. (bits and mantissa are positive: signed compares and shifts.)
  const Int mantissa = (bits & 0x000FFFFFFFFFFFFF) | 0x3FF0000000000000;  // [1, 2)
  const Int high = oneIf(mantissa > 0x3FF6A09E667F3BCD);  // > 1.4142135623730951 (as bits)
  const Int k = (bits >> 52) - 1023 + high;
  const Real m = bitCast<Real>(mantissa - (high << 52));
  const Int j = truncateToInt(m * 128 + 0.5);  // 91 … 181
  const Real c = toDouble(j) * (1.0 / 128);
  const Real s = (m - c) / (m + c);
  const Real s2 = s * s;
  const Real tail = 2 * s + s * (s2 * (2.0 / 3 + s2 * (2.0 / 5 + s2 * (2.0 / 7))));
  const Real kd = toDouble(k);
  return kd * kLn2Hi + ((lookup(kLnTable, j - 90) + tail) + kd * kLn2Lo);
}

// e^y for |y| < 700 (the caller checks the range; transferExp below).
template <typename Real>
FLAREKIT_LANES_INLINE Real transferExpCore(Real y) {
  using Int = IntFor<Real>;
  // k = round(64·y / ln 2) by the 1.5·2^52 shift (exact for |64·y / ln 2| < 2^51).
  constexpr double kShift = 6755399441055744.0;
  const Real kd = (y * (64 / 0.69314718055994530942) + kShift) - kShift;
  const Real r = (y - kd * (kLn2Hi / 64)) - kd * (kLn2Lo / 64);
  const Int k = roundedToInt(kd);
  const Real e = 1 + r * (1 + r * (1.0 / 2 + r * (1.0 / 6 + r * (1.0 / 24 + r * (1.0 / 120)))));
  // 2^(k/64) = 2^(k >> 6)·2^((k & 63)/64)
  const Real scale = bitCast<Real>(((k >> 6) + 1023) << 52);
  return lookup(kExp2Table, k & 63) * e * scale;
}

// The smallest normal double: below it (subnormals, 0) transferLog leaves the fast path.
inline constexpr double kSmallestNormal = 2.2250738585072014e-308;
// |y| ≥ this leaves transferExp's fast path.
inline constexpr double kExpFastLimit = 700.0;

inline double transferLog(double x) {
  if (!(x >= kSmallestNormal) || !(x <= 1.7976931348623157e308)) return std::log(x);
  return transferLogCore(x);
}

inline double transferExp(double y) {
  if (!(y > -kExpFastLimit && y < kExpFastLimit)) return std::exp(y);
  return transferExpCore(y);
}

}  // namespace flarekit::model::detail

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
