// The lanes of a host kernel's block (`chain_kernel.cc`): how many chains advance together,
// the loop over them that vectorises (`ForLanes`), the rows that are one value for every lane
// (`UniformRows`) and the buffer that writes a block's recorded samples out (`SampleBuffer`).
#pragma once

#ifdef __AVX512F__
#include <immintrin.h>
#endif

#include <cstdint>
#include <cstring>
#include <vector>

namespace hertzchain {

// Chains advanced together (the vectorised axis): blocks of 64 (measured best on a 2-core
// AVX-512 EPYC against 16, 32 and 128: the block's state stays in L1/L2), the remainder of
// the batch in blocks of 8 (one AVX-512 vector) and the last few chains one at a time (a
// single chain in an 8-lane block ran at half the speed of the JAX kernel).
// The lane loops carry `#pragma GCC unroll 8` (a 64-lane block is eight AVX-512 vectors,
// sixteen AVX2 ones): GCC 12 left the full kernel's sweep rolled, one vector at a time,
// which cost it 30 % (one core: 5.4e8 against 7.7e8 bead-steps/s, N = 21, eta and mu on).
constexpr int64_t kWideLanes = 64;
constexpr int64_t kNarrowLanes = 8;
// The full kernel's last 2-4 chains: one AVX2 vector (an AVX-512 core that splits 512-bit
// operations in two runs it in half the time of a partial 8-lane block).
constexpr int64_t kQuarterLanes = 4;
// `body(j)` for every lane j of a block of kLanes chains, vectorised (the lanes are
// independent), and for a 64-lane block unrolled in full (see above); narrower blocks are
// one or a few vectors already (unrolled before vectorisation, the tangent run of an
// 8-lane block was 4x slower). The loop and its bodies (`HC_LANES`) are always inlined: the
// tangent sweep's body, with its contact law on dual numbers, is larger than GCC 12 inlines
// on its own, and a loop that calls it per lane stays scalar (3.5x the instructions).
// `kRolled`: never unrolled (`#pragma GCC unroll 1`), where unrolling it let GCC vectorise an
// outer loop instead (the driven kernel's kick, `driven_kernel.cc`).
#define HC_LANES __attribute__((always_inline))
template <int64_t kLanes, bool kRolled = false, class Body>
HC_LANES inline void ForLanes(const Body& body) {
  if constexpr (kRolled) {
#pragma GCC ivdep
#pragma GCC unroll 1
    for (int64_t j = 0; j < kLanes; ++j) body(j);
  } else if constexpr (kLanes == 64) {
#pragma GCC ivdep
#pragma GCC unroll 8
    for (int64_t j = 0; j < kLanes; ++j) body(j);
  } else {
#pragma GCC ivdep
    for (int64_t j = 0; j < kLanes; ++j) body(j);
  }
}
constexpr int64_t kSampleBuffer = 8;    // samples kept per chain before they are written out (a cache line)

// Whether every lane of row r of a (rows, kLanes) block holds the same bits: the row is
// then read as one broadcast value (the same numbers, one load less per lane and step, and
// a block small enough for L1).
template <int64_t kLanes>
std::vector<char> UniformRows(const double* block, int64_t rows) {
  std::vector<char> uniform(rows);
  for (int64_t r = 0; r < rows; ++r) {
    bool same = true;
    for (int64_t j = 1; j < kLanes; ++j)
      same = same && std::memcmp(&block[r * kLanes + j], &block[r * kLanes], sizeof(double)) == 0;
    uniform[r] = same;
  }
  return uniform;
}

#ifdef __AVX512F__
// Rows in[s * stride + 0..7], s = 0..7, written as columns: dst[j][s] = in[s * stride + j]
// (in registers: the scalar copy of a buffer's flush cost an eighth of the conservative run).
inline void Transpose8x8(const double* in, int64_t stride, double* const* dst) {
  __m512d r[8], t[8], u[8];
  for (int s = 0; s < 8; ++s) r[s] = _mm512_loadu_pd(in + s * stride);
  for (int s = 0; s < 8; s += 2) {
    t[s] = _mm512_unpacklo_pd(r[s], r[s + 1]);      // columns 0 2 4 6 of rows s, s + 1
    t[s + 1] = _mm512_unpackhi_pd(r[s], r[s + 1]);  // columns 1 3 5 7
  }
  const __m512i even = _mm512_set_epi64(13, 12, 5, 4, 9, 8, 1, 0);
  const __m512i odd = _mm512_set_epi64(15, 14, 7, 6, 11, 10, 3, 2);
  for (int h = 0; h < 8; h += 4)
    for (int k = 0; k < 2; ++k) {
      u[h + k] = _mm512_permutex2var_pd(t[h + k], even, t[h + k + 2]);      // columns k, k + 4 of 4 rows
      u[h + k + 2] = _mm512_permutex2var_pd(t[h + k], odd, t[h + k + 2]);  // columns k + 2, k + 6
    }
  const __m512i low = _mm512_set_epi64(11, 10, 9, 8, 3, 2, 1, 0);
  const __m512i high = _mm512_set_epi64(15, 14, 13, 12, 7, 6, 5, 4);
  for (int k = 0; k < 4; ++k) {  // u[k]: columns k and k + 4 of rows 0-3; u[k + 4]: of rows 4-7
    _mm512_storeu_pd(dst[k], _mm512_permutex2var_pd(u[k], low, u[k + 4]));
    _mm512_storeu_pd(dst[k + 4], _mm512_permutex2var_pd(u[k], high, u[k + 4]));
  }
}
#endif

// The samples of a block's recorded channels, (sets, n_channels, kSampleBuffer, kLanes):
// a sample's lanes side by side (contiguous stores in the step), written out every
// kSampleBuffer samples as one cache line per chain and channel.
template <int64_t kLanes>
struct SampleBuffer {
  int64_t n_channels, sets, valid, buffered = 0, written = 0;  // valid: the block's real chains
  std::vector<double> data;
  SampleBuffer(int64_t n_channels_, int64_t sets_, int64_t valid_)
      : n_channels(n_channels_), sets(sets_), valid(valid_), data(sets_ * n_channels_ * kSampleBuffer * kLanes) {}
  // the lanes of set `set`, channel c at the current sample
  double* slot(int64_t set, int64_t c) { return &data[((set * n_channels + c) * kSampleBuffer + buffered) * kLanes]; }
  // `out(set, c, j)`: where the trace of lane j's chain, channel c (set `set`), starts
  template <class Out>
  void advance(Out out) {
    if (++buffered == kSampleBuffer) flush(out);
  }
  template <class Out>
  void flush(Out out) {
    for (int64_t set = 0; set < sets; ++set)
      for (int64_t c = 0; c < n_channels; ++c) {
        const double* in = &data[(set * n_channels + c) * kSampleBuffer * kLanes];
#ifdef __AVX512F__
        if (kLanes % 8 == 0 && buffered == 8 && valid == kLanes) {  // whole: 8 x 8 transposes
          for (int64_t j0 = 0; j0 < kLanes; j0 += 8) {
            double* dst[8];
            for (int64_t j = 0; j < 8; ++j) dst[j] = out(set, c, j0 + j) + written;
            Transpose8x8(in + j0, kLanes, dst);
          }
          continue;
        }
#endif
        for (int64_t j = 0; j < valid; ++j) {
          double* dst = out(set, c, j) + written;
          for (int64_t s = 0; s < buffered; ++s) dst[s] = in[s * kLanes + j];
        }
      }
    written += buffered;
    buffered = 0;
  }
};

}  // namespace hertzchain
