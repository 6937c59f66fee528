/* smooth.cpp: a C++ agent (nerve.hpp) that smooths a nerve::Scalar: an
 * exponential moving average of input `in` on output `out`, with the
 * weight of a new value as parameter `alpha` (0.01 to 1, changed at run
 * time by `nerve param set smooth alpha 0.5`). */
#include "nerve.hpp"

int main(int argc, char **argv) {
  nerve::input<nerve_Scalar> in;
  nerve::output<nerve_Scalar> out;
  nerve::param_f64 alpha;
  bool primed = false;
  double value = 0.0;

  nerve::agent smooth("smooth");
  smooth
      .on_init([&](nerve::setup &s) {
        in = s.input<nerve_Scalar>("in");
        out = s.output<nerve_Scalar>("out");
        alpha = s.param("alpha", 0.3, 0.01, 1.0);
      })
      .on_step([&](nerve::context &c) {
        const double a = c.param(alpha);
        while (const nerve_Scalar *x = c.take(in)) {
          value = primed ? a * x->value + (1.0 - a) * value : x->value;
          primed = true;
          auto slot = c.loan(out);
          slot->value = value;
          slot->stamp_ns = x->stamp_ns;
          slot.send();
        }
      });
  return smooth.run(argc, argv);
}
