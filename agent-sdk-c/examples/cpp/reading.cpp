/* reading.cpp: a C++ agent with a payload type of its own, lab::Reading,
 * the same layout as examples/c/reading.c's, given to nerve.hpp with
 * NERVE_HPP_OWN_TYPE: its ports are typed by the struct as for a built-in
 * type, nerve checks the layout when they are declared, and the router
 * connects them to the C agent's lab::Reading (same layout) and refuses
 * another layout of that name.
 *
 * Every 20 ms it sends a reading on `out` (`value` the cycle, `id` how
 * many readings it has taken from `in` so far, samples 1.5, 2.5, 3.5).
 * Built with -DREADING_TEST it is instead its own test: the same agent in
 * nerve's test harness (nerve::harness), no router. */
#include "nerve.hpp"

#include <cstdint>
#include <cstdio>

struct reading {
  double value;
  std::uint32_t id;
  float samples[3];
};

static const nerve_field reading_fields[] = {
    NERVE_FIELD(reading, value, NERVE_F64),
    NERVE_FIELD(reading, id, NERVE_U32),
    NERVE_FIELD_ARRAY(reading, samples, NERVE_F32),
};
static const nerve_type reading_type = NERVE_TYPE(reading, "lab::Reading", reading_fields);
NERVE_HPP_OWN_TYPE(reading, reading_type)

/* The agent's ports and what it counts. */
struct reader {
  nerve::input<reading> in;
  nerve::output<reading> out;
  std::uint32_t taken = 0;
};

static void define(nerve::agent &a, reader &r) {
  a.on_init([&r](nerve::setup &s) {
     r.in = s.input<reading>("in");
     r.out = s.output<reading>("out");
   }).on_step([&r](nerve::context &c) {
    while (c.take(r.in) != nullptr) {
      r.taken++;
    }
    nerve::loan<reading> l = c.loan(r.out);
    l->value = static_cast<double>(c.cycle());
    l->id = r.taken;
    l->samples[0] = 1.5f;
    l->samples[1] = 2.5f;
    l->samples[2] = 3.5f;
    l.send();
  });
}

#ifndef READING_TEST
int main(int argc, char **argv) {
  reader r;
  nerve::agent a("cppreading", 20000000u);
  define(a, r);
  return a.run(argc, argv);
}
#else
int main() {
  try {
    reader r;
    nerve::agent a("cppreading", 20000000u);
    define(a, r);
    nerve::harness h(a);
    h.send("in", reading{7.0, 1, {0, 0, 0}});
    h.send("in", reading{8.0, 2, {0, 0, 0}});
    if (h.advance(40000000u) != 2) {
      std::printf("FAIL two steps in 40 ms\n");
      return 1;
    }
    std::optional<reading> first = h.output<reading>("out");
    std::optional<reading> second = h.output<reading>("out");
    if (!first || !second || h.output<reading>("out") || first->value != 0.0 || first->id != 2 ||
        second->value != 1.0 || first->samples[2] != 3.5f) {
      std::printf("FAIL the readings sent\n");
      return 1;
    }
    std::printf("PASSED\n");
    return 0;
  } catch (const std::exception &e) {
    std::printf("FAIL %s\n", e.what());
    return 1;
  }
}
#endif
