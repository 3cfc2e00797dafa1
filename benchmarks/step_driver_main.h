// The `main` of the step drivers (`native_step_driver.cc`, `driven_thread_step_driver.cc`):
// runs the one of `runs` that the first argument names, then prints `checksum` (what the
// runs add their results to), or says the usage and returns 2.
#pragma once

#include <cstddef>
#include <cstdio>
#include <cstring>

struct NamedRun {
  const char* name;
  void (*run)();
};

template <std::size_t N>
int RunNamed(int argc, char** argv, const NamedRun (&runs)[N], const double& checksum) {
  const char* wanted = argc > 1 ? argv[1] : "";
  for (const NamedRun& r : runs) {
    if (std::strcmp(wanted, r.name) == 0) {
      r.run();
      std::printf("%.17g\n", checksum);
      return 0;
    }
  }
  std::fprintf(stderr, "usage: %s ", argv[0]);
  for (std::size_t k = 0; k < N; ++k) std::fprintf(stderr, "%s%s", k > 0 ? "|" : "", runs[k].name);
  std::fprintf(stderr, "\n");
  return 2;
}
