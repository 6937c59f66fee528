/* relay.cpp: a nerve agent written in C++17 with nerve.hpp. It republishes
 * every nerve::Tick arriving on `in` on `out`, read and written in place in
 * shared memory, and relays only one tick of every `every` (a parameter,
 * 1 to 1000, changed at run time by `nerve param set cpprelay every N`).
 *
 * Build (from the nerve tree, after `cargo build -p nerve-agent-c`):
 *   g++ -std=c++17 -Wall -Wextra -I agent-sdk-c/include agent-sdk-c/examples/cpp/relay.cpp \
 *       -L target/debug -lnerve -Wl,-rpath,$PWD/target/debug -o cpprelay
 * and run it as any agent: from a launch file (`exe = "/path/to/cpprelay"`),
 * or `./cpprelay --describe`. */
#include "nerve.hpp"

#include <cstdint>
#include <cstdio>

// Build with -DCPPRELAY_EVERY_DEFAULT=0 for a relay whose parameter's
// default is out of its bounds: its init throws, and the agent fails to
// start with nerve's message instead of crashing.
#ifndef CPPRELAY_EVERY_DEFAULT
#define CPPRELAY_EVERY_DEFAULT 1.0
#endif

int main(int argc, char **argv) {
  nerve::input<nerve_Tick> in;
  nerve::output<nerve_Tick> out;
  nerve::param_f64 every;
  std::uint64_t seen = 0;
  std::uint64_t relayed = 0;

  nerve::agent relay("cpprelay");
  relay
      .on_init([&](nerve::setup &s) {
        in = s.input<nerve_Tick>("in");
        out = s.output<nerve_Tick>("out");
        every = s.param("every", CPPRELAY_EVERY_DEFAULT, 1.0, 1000.0);
      })
      .on_step([&](nerve::context &c) {
        const auto n = static_cast<std::uint64_t>(c.param(every));
        while (const nerve_Tick *t = c.take(in)) {
          if (seen++ % n != 0) {
            continue;
          }
          auto slot = c.loan(out);  // in shared memory: written in place
          slot->seq = t->seq;
          slot->stamp_ns = t->stamp_ns;
          slot.send();
          relayed++;
        }
      })
      .on_stop([&](nerve::context &) {
        std::fprintf(stderr, "cpprelay: stopping after %llu ticks\n", static_cast<unsigned long long>(relayed));
      });
  return relay.run(argc, argv);
}
