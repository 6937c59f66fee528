/* harness_check.h: the checks the C harness tests share (relay_test.c,
 * seq_call_test.c): a count of failures, `expect` (a status, and a message
 * with any failure) and `expect_true`, each printing "ok" or "FAIL" and
 * what was checked. Include it once, after nerve.h. */
#ifndef NERVE_HARNESS_CHECK_H
#define NERVE_HARNESS_CHECK_H

#include <stdio.h>
#include <string.h>

static int failures = 0;

/* Checks that `got` is `want`, and that a failure has a message. */
static void expect(const char *what, nerve_status got, nerve_status want) {
  const char *msg = nerve_last_error();
  if (got != want) {
    printf("FAIL %s: status %d, not %d (%s)\n", what, (int)got, (int)want, msg);
    failures++;
  } else if (want != NERVE_OK && strlen(msg) == 0) {
    printf("FAIL %s: status %d without a message\n", what, (int)got);
    failures++;
  } else {
    printf("ok %s%s%s\n", what, want == NERVE_OK ? "" : ": ", msg);
  }
}

static void expect_true(const char *what, int ok) {
  printf("%s %s\n", ok ? "ok" : "FAIL", what);
  failures += !ok;
}

#endif
