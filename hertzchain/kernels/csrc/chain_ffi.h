// The argument lists the fused kernels' FFI handlers share (`chain_kernel.cc`, the host
// kernels; `chain_kernel_thread.cu`, the one-thread-per-chain kernels), in the order
// `hertzchain.native` passes them: one definition for every handler. Each function takes
// an `ffi::Ffi::Bind()` binding (with the context its kernel needs, and, for the host
// kernels, the recorded channels as a buffer) and appends its arguments or attributes.
#pragma once

#include <cstdint>
#include <utility>

#include "xla/ffi/api/ffi.h"

namespace hertzchain {

using F64Buffer = xla::ffi::Buffer<xla::ffi::F64>;

// The conservative kernel's state and parameters: state0 (x, v; for the full kernels x,
// v, a), inv_mass, kappa, overlap0, spring, external, each (rows, 1 or B)
template <class Binding>
auto ChainArgs(Binding&& binding) {
  return std::forward<Binding>(binding)
      .template Arg<F64Buffer>()   // state0
      .template Arg<F64Buffer>()   // inv_mass
      .template Arg<F64Buffer>()   // kappa
      .template Arg<F64Buffer>()   // overlap0
      .template Arg<F64Buffer>()   // spring
      .template Arg<F64Buffer>();  // external
}

// The full kernels' state and parameters: `ChainArgs`, then eta, friction (mu g) and the
// linear dashpot (N s/m), each (1, 1 or B). The tangent kernels take them twice: the values,
// then their tangents in the same order.
template <class Binding>
auto FullArgs(Binding&& binding) {
  return ChainArgs(std::forward<Binding>(binding))
      .template Arg<F64Buffer>()   // eta
      .template Arg<F64Buffer>()   // friction (mu g)
      .template Arg<F64Buffer>();  // dashpot
}

// Every kernel's first attributes: the step (s) and the steps per recorded sample
template <class Binding>
auto StepAttrs(Binding&& binding) {
  return std::forward<Binding>(binding)
      .template Attr<double>("dt")
      .template Attr<int64_t>("steps_per_sample");
}

// The conservative kernel's attributes
template <class Binding>
auto ForwardAttrs(Binding&& binding) {
  return StepAttrs(std::forward<Binding>(binding))
      .template Attr<int64_t>("preload")
      .template Attr<int64_t>("springs")
      .template Attr<int64_t>("books");
}

// The full kernels' attributes (extras: preload or springs; dashpot: compile the linear
// dashpot's terms in, with viscous only)
template <class Binding>
auto FullAttrs(Binding&& binding) {
  return StepAttrs(std::forward<Binding>(binding))
      .template Attr<int64_t>("viscous")
      .template Attr<int64_t>("friction")
      .template Attr<int64_t>("extras")
      .template Attr<int64_t>("dashpot");
}

}  // namespace hertzchain
