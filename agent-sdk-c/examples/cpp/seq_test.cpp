/* seq_test.cpp: sequences and calls through nerve.hpp (issue 43), on the
 * C test harness: a C++ agent with a sequence input and output of its own
 * element and header types (the Rust test agent `detector`'s layout), a
 * service and a client declared by their payload structs. It reads a
 * queued sequence in place (range-for over the elements), sends one of 3
 * elements written in place, and is refused a loan past its max_len with
 * nerve::error(NERVE_TOO_LONG). Its service is answered with a lambda
 * where the harness carries calls (NERVE_NOT_IN_HARNESS where it does not).
 *
 * Run by agent-sdk-c/tests/c_harness.rs. Exits 0 when every check passed. */
#include "nerve.hpp"

#include <cstdio>

struct detection {
  float x;
  float y;
  std::uint32_t id;
};
static const nerve_field detection_fields[] = {NERVE_FIELD(detection, x, NERVE_F32),
                                               NERVE_FIELD(detection, y, NERVE_F32),
                                               NERVE_FIELD(detection, id, NERVE_U32)};
static const nerve_type detection_type = NERVE_TYPE(detection, "acme::Detection", detection_fields);
NERVE_HPP_OWN_TYPE(detection, detection_type)

struct dets_header {
  std::uint64_t frame;
  std::uint32_t count;
  std::uint8_t pad[4];
};
static const nerve_field header_fields[] = {NERVE_FIELD(dets_header, frame, NERVE_U64),
                                            NERVE_FIELD(dets_header, count, NERVE_U32)};
static const nerve_type header_type = NERVE_TYPE(dets_header, "acme::DetectionsHeader", header_fields);
NERVE_HPP_OWN_TYPE(dets_header, header_type)

/* A sequence sample as it lies in memory: the header, then N elements. */
template <int N>
struct sample {
  dets_header h;
  detection d[N];
};

int main() {
  int failures = 0;
  auto expect = [&](const char *what, bool ok) {
    std::printf("%s %s\n", ok ? "ok" : "FAIL", what);
    failures += !ok;
  };
  nerve::seq_input<detection, dets_header> in;
  nerve::seq_output<detection, dets_header> out;
  nerve::server<nerve_Tick, nerve_Scalar> plan;
  nerve::client<nerve_Tick, nerve_Scalar> planner;
  nerve::seq_server<nerve_Tick, nerve_Scalar, nerve_Tick> path;
  nerve::seq_client<nerve_Tick, nerve_Scalar, nerve_Tick> pather;
  std::size_t sent = 0, taken = 0;
  std::size_t read = 0, bad = 0, refused = 0;
  nerve::agent a("cppseq", 20000000);
  a.on_init([&](nerve::setup &s) {
    in = s.input_seq<detection, dets_header>("dets_in");
    out = s.output_seq<detection, dets_header>("dets", 8);
    plan = s.serve<nerve_Tick, nerve_Scalar>("plan");
    planner = s.client<nerve_Tick, nerve_Scalar>("planner", 300000000);
    path = s.serve_seq<nerve_Tick, nerve_Scalar, nerve_Tick>("path", 16);
    pather = s.client_seq<nerve_Tick, nerve_Scalar, nerve_Tick>("pather", 300000000);
  });
  a.on_step([&](nerve::context &c) {
    while (auto s = c.take(in)) {
      read++;
      std::uint32_t j = 0;
      for (const detection &d : *s) {
        bad += d.id != j++;
      }
      bad += s->header().count != s->size();
    }
    auto l = c.loan(out, 3);
    l.header().frame = c.cycle() + 1;
    l.header().count = static_cast<std::uint32_t>(l.size());
    std::uint32_t j = 0;
    for (detection &d : l) {
      d = detection{static_cast<float>(j), 0.0f, j};
      j++;
    }
    l.send();
    try {
      c.loan(out, 9);
    } catch (const nerve::error &e) {
      refused += e.status() == NERVE_TOO_LONG;
    }
    try {
      c.serve(plan, [](const nerve_Tick &t) { return nerve_Scalar{2.0 * static_cast<double>(t.seq), t.stamp_ns}; });
    } catch (const nerve::error &e) {
      if (e.status() != NERVE_NOT_IN_HARNESS) {
        throw;
      }
    }
    /* a sequence service: nothing waits in the harness, so nothing is answered */
    c.serve_seq(path, [](const nerve_Tick &t, nerve::answer_loan<nerve_Scalar, nerve_Tick> &ans) {
      if (auto l = ans.loan(t.seq)) {
        l->header() = t;
        for (std::size_t i = 0; i < l->size(); i++) {
          (*l)[i] = nerve_Scalar{static_cast<double>(i), t.stamp_ns};
        }
      }
    });
    /* a sequence client: in the harness its call goes to the test, which does not answer it */
    if (c.cycle() == 0) {
      sent += c.call(pather, nerve_Tick{3, 0}) != 0;
    }
    std::string why;
    if (c.take_answer(pather, &why)) {
      taken++;
    }
  });
  nerve::harness h(a);
  sample<4> s4{};
  s4.h.frame = 7;
  s4.h.count = 4;
  for (std::uint32_t k = 0; k < 4; k++) {
    s4.d[k] = detection{0.0f, 7.0f, k};
  }
  h.send("dets_in", s4);
  h.advance(20000000);
  auto o = h.output<sample<8>>("dets");
  expect("a sequence of 3 sent, written in place",
         o && o->h.frame == 1 && o->h.count == 3 && o->d[0].id == 0 && o->d[2].id == 2 && o->d[2].x == 2.0f);
  expect("the queued sequence read in place, every element right", read == 1 && bad == 0);
  expect("a loan past max_len refused with NERVE_TOO_LONG", refused == 1);
  expect("a sequence client's call sent (to the test), not answered yet", sent == 1 && taken == 0);
  std::printf("%s: %d failure(s)\n", failures ? "FAILED" : "PASSED", failures);
  return failures ? 1 : 0;
}
