/* bench_payloads.h: the payloads of `nerve bench c` as C structs, for the
 * C and C++ pongs (pong.c, pong.cpp). They are the bench's Rust payloads
 * (bench/src/payloads.rs: `nerve::bench::Small8`, `Frame4k`, `Frame230k`,
 * `Frame1080p`), declared to nerve as the agent's own types (NERVE_TYPE):
 * nerve computes their fingerprint from the field table, and the router
 * connects them to the Rust ping only if the layouts are the same.
 * The first 8 bytes of each are the round trip's sequence number. */
#ifndef NERVE_BENCH_PAYLOADS_H
#define NERVE_BENCH_PAYLOADS_H

#include "nerve.h"
#include "nerve_types.h"

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct bench_Small8 {
  uint64_t seq;
} bench_Small8;

typedef struct bench_Frame4k {
  uint64_t seq;
  uint8_t rest[4096 - 8];
} bench_Frame4k;

typedef struct bench_Frame230k {
  uint64_t seq;
  uint8_t rest[320 * 240 * 3 - 8];
} bench_Frame230k;

typedef struct bench_Frame1080p {
  uint64_t seq;
  uint8_t rest[1920 * 1080 * 3 - 8];
} bench_Frame1080p;

NERVE_STATIC_ASSERT(sizeof(bench_Small8) == 8, "Small8 is 8 bytes");
NERVE_STATIC_ASSERT(sizeof(bench_Frame230k) == 230400, "Frame230k is 230,400 bytes");
NERVE_STATIC_ASSERT(sizeof(bench_Frame1080p) == 6220800, "Frame1080p is 6,220,800 bytes");

static const nerve_field bench_Small8_fields[] = {NERVE_FIELD(bench_Small8, seq, NERVE_U64)};
static const nerve_field bench_Frame4k_fields[] = {NERVE_FIELD(bench_Frame4k, seq, NERVE_U64),
                                                   NERVE_FIELD_ARRAY(bench_Frame4k, rest, NERVE_U8)};
static const nerve_field bench_Frame230k_fields[] = {NERVE_FIELD(bench_Frame230k, seq, NERVE_U64),
                                                     NERVE_FIELD_ARRAY(bench_Frame230k, rest, NERVE_U8)};
static const nerve_field bench_Frame1080p_fields[] = {NERVE_FIELD(bench_Frame1080p, seq, NERVE_U64),
                                                      NERVE_FIELD_ARRAY(bench_Frame1080p, rest, NERVE_U8)};

static const nerve_type bench_Small8_type = NERVE_TYPE(bench_Small8, "nerve::bench::Small8", bench_Small8_fields);
static const nerve_type bench_Frame4k_type =
    NERVE_TYPE(bench_Frame4k, "nerve::bench::Frame4k", bench_Frame4k_fields);
static const nerve_type bench_Frame230k_type =
    NERVE_TYPE(bench_Frame230k, "nerve::bench::Frame230k", bench_Frame230k_fields);
static const nerve_type bench_Frame1080p_type =
    NERVE_TYPE(bench_Frame1080p, "nerve::bench::Frame1080p", bench_Frame1080p_fields);

/* The layout of the payload of `size` bytes, or NULL for a size the bench has none of. */
static inline const nerve_type *bench_payload_of(size_t size) {
  switch (size) {
    case sizeof(bench_Small8):
      return &bench_Small8_type;
    case sizeof(bench_Frame4k):
      return &bench_Frame4k_type;
    case sizeof(bench_Frame230k):
      return &bench_Frame230k_type;
    case sizeof(bench_Frame1080p):
      return &bench_Frame1080p_type;
    default:
      return NULL;
  }
}

/* The value of `--size N` among the agent's own arguments (after `--`),
 * as the Rust pong takes it; 8 when not given, 0 when not a number. */
static inline size_t bench_size_arg(int argc, char **argv) {
  int own = 0;
  for (int i = 1; i < argc; i++) {
    if (!own) {
      own = strcmp(argv[i], "--") == 0;
    } else if (strcmp(argv[i], "--size") == 0 && i + 1 < argc) {
      char *end = NULL;
      unsigned long long v = strtoull(argv[i + 1], &end, 10);
      return (end != NULL && *end == '\0' && end != argv[i + 1]) ? (size_t)v : 0;
    }
  }
  return 8;
}

#endif /* NERVE_BENCH_PAYLOADS_H */
