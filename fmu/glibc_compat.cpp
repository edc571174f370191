// arc4random for MachineTwin.so, so that the binary does not need glibc 2.36.
//
// The static libstdc++ linked into the FMU implements std::random_device with
// glibc's arc4random, which appeared in glibc 2.36; that one reference made
// the whole FMU refuse to load on older systems (Ubuntu 22.04 has 2.35). The
// model never draws random numbers; this definition, local to the binary (the
// version script exports fmi2* only), satisfies the reference with
// getentropy (glibc 2.25) instead. docs/fmu.md lists what the binary needs.
#include <sys/random.h>

#include <cstdint>
#include <cstdio>
#include <exception>

extern "C" std::uint32_t arc4random(void) {
  std::uint32_t v = 0;
  if (getentropy(&v, sizeof v) == 0) return v;
  if (std::FILE* f = std::fopen("/dev/urandom", "rb")) {
    const std::size_t got = std::fread(&v, sizeof v, 1, f);
    std::fclose(f);
    if (got == 1) return v;
  }
  std::fputs("MachineTwin: no source of random bytes (getentropy and /dev/urandom failed)\n", stderr);
  std::terminate();
}
