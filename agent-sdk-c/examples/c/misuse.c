/* misuse.c: every function of nerve.h called the wrong way (NULL handles
 * and out-pointers, no agent) from plain C: each must return its status
 * with a message, never crash. Run by agent-sdk-c/tests/c_agent.rs;
 * prints one line per call and exits 1 if any answer is wrong. */
#include "nerve.h"

#include <stdio.h>
#include <string.h>

static int check(const char *what, nerve_status got, nerve_status want) {
  const char *msg = nerve_last_error();
  if (got != want) {
    printf("FAIL %s: status %d, not %d (%s)\n", what, (int)got, (int)want, msg);
    return 1;
  }
  if (want != NERVE_OK && (msg == NULL || strlen(msg) == 0)) {
    printf("FAIL %s: status %d without a message\n", what, (int)got);
    return 1;
  }
  printf("ok %s: %s\n", what, msg);
  return 0;
}

int main(void) {
  int bad = 0;
  nerve_port port = 0;
  nerve_param param = 0;
  const void *data = NULL;
  size_t len = 0;
  void *slot = NULL;
  uint64_t cycle = 0;
  double value = 0;
  bad += check("setup_input(NULL setup)", nerve_setup_input(NULL, "in", "nerve::Tick", 16, 8, 0, &port), NERVE_NULL_POINTER);
  bad += check("setup_output(NULL setup)", nerve_setup_output(NULL, "out", "nerve::Tick", 16, 8, 0, &port), NERVE_NULL_POINTER);
  bad += check("setup_param_f64(NULL setup)", nerve_setup_param_f64(NULL, "gain", 1.0, 0.0, 2.0, &param), NERVE_NULL_POINTER);
  bad += check("take(NULL ctx)", nerve_take(NULL, 1, &data, &len), NERVE_NULL_POINTER);
  bad += check("take(NULL data)", nerve_take(NULL, 1, NULL, &len), NERVE_NULL_POINTER);
  bad += check("latest(NULL ctx)", nerve_latest(NULL, 1, &data, &len), NERVE_NULL_POINTER);
  bad += check("loan(NULL ctx)", nerve_loan(NULL, 65536, &slot), NERVE_NULL_POINTER);
  bad += check("loan(NULL data)", nerve_loan(NULL, 65536, NULL), NERVE_NULL_POINTER);
  bad += check("send(NULL ctx)", nerve_send(NULL, 65536), NERVE_NULL_POINTER);
  bad += check("cycle(NULL ctx)", nerve_cycle(NULL, &cycle), NERVE_NULL_POINTER);
  bad += check("request_stop(NULL ctx)", nerve_request_stop(NULL), NERVE_NULL_POINTER);
  bad += check("param_f64(NULL ctx)", nerve_param_f64(NULL, 1, &value), NERVE_NULL_POINTER);
  /* sequences and calls */
  nerve_seq seq = {&seq, &seq, 1};
  nerve_seq_loan sl = {&sl, &sl, 1};
  uint64_t call = 1;
  char buf[16] = {0};
  bad += check("setup_input_seq(NULL setup)", nerve_setup_input_seq(NULL, "in", NULL, NULL, &port), NERVE_NULL_POINTER);
  bad += check("setup_output_seq(NULL setup)", nerve_setup_output_seq(NULL, "out", NULL, NULL, 8, &port), NERVE_NULL_POINTER);
  bad += check("take_seq(NULL ctx)", nerve_take_seq(NULL, 1, &seq), NERVE_NULL_POINTER);
  bad += check("latest_seq(NULL ctx)", nerve_latest_seq(NULL, 1, &seq), NERVE_NULL_POINTER);
  bad += check("loan_seq(NULL ctx)", nerve_loan_seq(NULL, 65536, 1, &sl), NERVE_NULL_POINTER);
  bad += check("loan_seq(NULL loan)", nerve_loan_seq(NULL, 65536, 1, NULL), NERVE_NULL_POINTER);
  bad += check("setup_serve(NULL setup)", nerve_setup_serve(NULL, "plan", NULL, NULL, &port), NERVE_NULL_POINTER);
  bad += check("setup_client(NULL setup)", nerve_setup_client(NULL, "planner", NULL, NULL, 0, &port), NERVE_NULL_POINTER);
  bad += check("serve(NULL answer function)", nerve_serve(NULL, 131072, NULL, NULL, NULL), NERVE_NULL_POINTER);
  bad += check("call(NULL ctx)", nerve_call(NULL, 196608, buf, 16, &call), NERVE_NULL_POINTER);
  bad += check("call_take(NULL ctx)", nerve_call_take(NULL, 196608, &call, buf, 16), NERVE_NULL_POINTER);
  bad += check("call_wait(NULL ctx)", nerve_call_wait(NULL, 196608, buf, 16, buf, 16), NERVE_NULL_POINTER);
  if (seq.header != NULL || seq.items != NULL || seq.len != 0 || sl.header != NULL || call != 0) {
    printf("FAIL a sequence or call out-pointer was set by a failed call\n");
    bad++;
  }
  if (data != NULL || len != 0 || slot != NULL) {
    printf("FAIL an out-pointer was set by a failed call\n");
    bad++;
  }
  int code = nerve_run(0, NULL, NULL, NULL);
  if (code != 2) {
    printf("FAIL nerve_run(NULL agent) returned %d, not 2\n", code);
    bad++;
  } else {
    printf("ok nerve_run(NULL agent): %s\n", nerve_last_error());
  }
  return bad ? 1 : 0;
}
