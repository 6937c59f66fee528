/* pong.cpp: the C++ pong of `nerve bench c` (row `cpp`), an event-driven
 * nerve agent written in C++17 with nerve.hpp: every sample arriving on
 * `in` is answered with one on `out`, as the Rust pong does. The port is
 * typed by the payload struct (bench_payloads.h, given to nerve.hpp with
 * NERVE_HPP_OWN_TYPE); the sample is read in place (context::take) and
 * only its sequence number is written, in place, in a slot that is not
 * zeroed (context::loan_uninit). Built with -DPONG_LOAN_ZEROED it loans
 * with context::loan, which zeroes the whole slot first.
 *
 * The bench compiles it at run time, with g++ -O2 against the release
 * libnerve, and starts it as any agent:
 *   cpppong --robot R --name cpppong-8 -- --size 8 */
#include "bench_payloads.h"
#include "nerve.hpp"

#include <cstdio>

NERVE_HPP_OWN_TYPE(bench_Small8, bench_Small8_type)
NERVE_HPP_OWN_TYPE(bench_Frame4k, bench_Frame4k_type)
NERVE_HPP_OWN_TYPE(bench_Frame230k, bench_Frame230k_type)
NERVE_HPP_OWN_TYPE(bench_Frame1080p, bench_Frame1080p_type)

namespace {

/* Runs the pong of payload T until it is stopped. */
template <class T>
int run_pong(int argc, char **argv) {
  nerve::input<T> in;
  nerve::output<T> out;
  nerve::agent pong("bench-cpppong");
  pong.on_init([&](nerve::setup &s) {
        in = s.input<T>("in");
        out = s.output<T>("out");
      })
      .on_step([&](nerve::context &c) {
        while (const T *t = c.take(in)) {
#ifdef PONG_LOAN_ZEROED
          auto slot = c.loan(out);
#else
          auto slot = c.loan_uninit(out);
#endif
          slot->seq = t->seq;
          slot.send();
        }
      });
  return pong.run(argc, argv);
}

}  // namespace

int main(int argc, char **argv) {
  switch (bench_size_arg(argc, argv)) {
    case sizeof(bench_Small8):
      return run_pong<bench_Small8>(argc, argv);
    case sizeof(bench_Frame4k):
      return run_pong<bench_Frame4k>(argc, argv);
    case sizeof(bench_Frame230k):
      return run_pong<bench_Frame230k>(argc, argv);
    case sizeof(bench_Frame1080p):
      return run_pong<bench_Frame1080p>(argc, argv);
    default:
      std::fprintf(stderr, "cpppong: no payload of that size; use --size 8, 4096, 230400 or 6220800\n");
      return 2;
  }
}
