/* nerve.hpp: a header-only C++17 wrapper over nerve's C API (nerve.h) and
 * its payload structs (nerve_types.h). Link libnerve as for a C agent.
 *
 *   #include "nerve.hpp"
 *   int main(int argc, char **argv) {
 *     nerve::input<nerve_Tick> in;
 *     nerve::output<nerve_Tick> out;
 *     nerve::agent a("cpprelay");
 *     a.on_init([&](nerve::setup &s) { in = s.input<nerve_Tick>("in"); out = s.output<nerve_Tick>("out"); });
 *     a.on_step([&](nerve::context &c) {
 *       while (const nerve_Tick *t = c.take(in)) c.send(out, *t);
 *     });
 *     return a.run(argc, argv);
 *   }
 *
 * Errors are exceptions: every nerve call that fails throws nerve::error
 * (a std::runtime_error holding the nerve_status and nerve_last_error()'s
 * text: what went wrong and what to do). "No sample waiting" is not an
 * error: take and latest return nullptr. An exception leaving a callback
 * never reaches nerve's Rust runtime: the wrapper catches it, prints
 * "KIND: init|start|step|stop: MESSAGE" to stderr and fails that call
 * (a failed init ends the agent, a failed step is counted as a C agent's).
 *
 * Threads and lifetimes are the C API's: init runs in main's thread (and
 * once more for --describe), start, step and stop in the agent's task
 * thread, never two at once. A sample pointer from take or latest, and a
 * loan, are valid until the callback returns.
 *
 * Ports are typed by their payload struct: any struct T with a
 * nerve::payload<T> specialisation (type_name, fingerprint), which every
 * type of nerve_types.h has, or an own type given by NERVE_HPP_OWN_TYPE. */
#ifndef NERVE_HPP
#define NERVE_HPP

#include "nerve.h"
#include "nerve_types.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace nerve {

/* The type name and layout fingerprint nerve knows payload struct T by. */
template <class T>
struct payload;

#define NERVE_HPP_PAYLOAD(T)                                   \
  template <>                                                  \
  struct payload<::T> {                                        \
    static constexpr const char *type_name = T##_TYPE_NAME;    \
    static constexpr std::uint64_t fingerprint = T##_FINGERPRINT; \
  };
NERVE_BUILTIN_PAYLOADS(NERVE_HPP_PAYLOAD)
#undef NERVE_HPP_PAYLOAD

/* A payload struct of the agent's own (a type not in nerve_types.h),
 * described as in C (NERVE_TYPE and NERVE_FIELD of nerve_types.h) and
 * given to nerve once, at global scope, with NERVE_HPP_OWN_TYPE:
 *
 *   struct reading { double value; std::uint32_t id; float samples[3]; };
 *   static const nerve_field reading_fields[] = {
 *       NERVE_FIELD(reading, value, NERVE_F64), NERVE_FIELD(reading, id, NERVE_U32),
 *       NERVE_FIELD_ARRAY(reading, samples, NERVE_F32)};
 *   static const nerve_type reading_type = NERVE_TYPE(reading, "lab::Reading", reading_fields);
 *   NERVE_HPP_OWN_TYPE(reading, reading_type)
 *
 * Then s.input<reading>("in"), c.take(in), c.loan(out), h.output<reading>
 * work as for a built-in type; nerve checks the layout when the port is
 * declared and the router against any other agent's type of that name. */
template <class T>
struct own_type;

#define NERVE_HPP_OWN_TYPE(T, layout)                                 \
  namespace nerve {                                                   \
  template <>                                                         \
  struct own_type<T> {                                                \
    static const nerve_type *get() noexcept { return &(layout); }     \
  };                                                                  \
  }

namespace detail {
/* Whether T is an own type (NERVE_HPP_OWN_TYPE) rather than a built-in one. */
template <class T, class = void>
struct is_own : std::false_type {};
template <class T>
struct is_own<T, std::void_t<decltype(own_type<T>::get())>> : std::true_type {};

/* The type name nerve knows T by. */
template <class T>
const char *type_name() noexcept {
  if constexpr (is_own<T>::value) {
    return own_type<T>::get()->type_name;
  } else {
    return payload<T>::type_name;
  }
}
}  // namespace detail

/* A failed nerve call: its status and nerve's message. */
class error : public std::runtime_error {
 public:
  error(nerve_status status, const std::string &what) : std::runtime_error(what), status_(status) {}
  /* The C API's status (NERVE_LAYOUT_MISMATCH, NERVE_STALE, ...). */
  nerve_status status() const noexcept { return status_; }

 private:
  nerve_status status_;
};

namespace detail {
/* Throws nerve::error for a status other than NERVE_OK, naming `call`. */
inline void check(nerve_status s, const char *call) {
  if (s != NERVE_OK) {
    throw error(s, std::string(call) + ": " + nerve_last_error());
  }
}
}  // namespace detail

/* An input port carrying T; a handle, cheap to copy. */
template <class T>
class input {
 public:
  input() = default;
  nerve_port handle() const noexcept { return port_; }

 private:
  friend class setup;
  explicit input(nerve_port p) : port_(p) {}
  nerve_port port_ = 0;
};

/* An output port carrying T; a handle, cheap to copy. */
template <class T>
class output {
 public:
  output() = default;
  nerve_port handle() const noexcept { return port_; }

 private:
  friend class setup;
  explicit output(nerve_port p) : port_(p) {}
  nerve_port port_ = 0;
};

/* A number parameter (nerve param set changes it at run time). */
class param_f64 {
 public:
  param_f64() = default;
  nerve_param handle() const noexcept { return param_; }

 private:
  friend class setup;
  explicit param_f64(nerve_param p) : param_(p) {}
  nerve_param param_ = 0;
};

/* The header of a sequence that has none (nerve::NoHeader). */
struct no_header {};

/* A sequence input: samples of a Header and any number of Elem (as a
 * Rust agent's SeqInput<Elem, Header>); a handle, cheap to copy. */
template <class Elem, class Header = no_header>
class seq_input {
 public:
  seq_input() = default;
  nerve_port handle() const noexcept { return port_; }

 private:
  friend class setup;
  explicit seq_input(nerve_port p) : port_(p) {}
  nerve_port port_ = 0;
};

/* A sequence output of at most the max_len it was declared with. */
template <class Elem, class Header = no_header>
class seq_output {
 public:
  seq_output() = default;
  nerve_port handle() const noexcept { return port_; }

 private:
  friend class setup;
  explicit seq_output(nerve_port p) : port_(p) {}
  nerve_port port_ = 0;
};

/* A service this agent answers: requests Req, answers Resp. */
template <class Req, class Resp>
class server {
 public:
  server() = default;
  nerve_port handle() const noexcept { return port_; }

 private:
  friend class setup;
  explicit server(nerve_port p) : port_(p) {}
  nerve_port port_ = 0;
};

/* A client of another agent's service of Req and Resp. */
template <class Req, class Resp>
class client {
 public:
  client() = default;
  nerve_port handle() const noexcept { return port_; }

 private:
  friend class setup;
  explicit client(nerve_port p) : port_(p) {}
  nerve_port port_ = 0;
};

/* A service this agent answers: requests Req, answers of a Header and
 * at most the declared max_len of Elem (a Rust serve_seq's). */
template <class Req, class Elem, class Header = no_header>
class seq_server {
 public:
  seq_server() = default;
  nerve_port handle() const noexcept { return port_; }

 private:
  friend class setup;
  explicit seq_server(nerve_port p) : port_(p) {}
  nerve_port port_ = 0;
};

/* A client of another agent's service of Req answered with sequences. */
template <class Req, class Elem, class Header = no_header>
class seq_client {
 public:
  seq_client() = default;
  nerve_port handle() const noexcept { return port_; }

 private:
  friend class setup;
  explicit seq_client(nerve_port p) : port_(p) {}
  nerve_port port_ = 0;
};

/* What init declares ports and parameters on; valid during init only. */
class setup {
 public:
  explicit setup(nerve_setup *s) noexcept : s_(s) {}

  /* Declares input `name` of payload T; throws nerve::error if nerve
   * refuses it (a name taken, a layout that is not nerve's). */
  template <class T>
  nerve::input<T> input(const char *name) {
    static_assert(std::is_trivially_copyable<T>::value, "a payload is a plain struct");
    nerve_port p = 0;
    if constexpr (detail::is_own<T>::value) {
      detail::check(nerve_setup_input_type(s_, name, own_layout<T>(), &p), "nerve_setup_input_type");
    } else {
      detail::check(
          nerve_setup_input(s_, name, payload<T>::type_name, sizeof(T), alignof(T), payload<T>::fingerprint, &p),
          "nerve_setup_input");
    }
    return nerve::input<T>(p);
  }

  /* Declares output `name` of payload T, as input does. */
  template <class T>
  nerve::output<T> output(const char *name) {
    static_assert(std::is_trivially_copyable<T>::value, "a payload is a plain struct");
    nerve_port p = 0;
    if constexpr (detail::is_own<T>::value) {
      detail::check(nerve_setup_output_type(s_, name, own_layout<T>(), &p), "nerve_setup_output_type");
    } else {
      detail::check(
          nerve_setup_output(s_, name, payload<T>::type_name, sizeof(T), alignof(T), payload<T>::fingerprint, &p),
          "nerve_setup_output");
    }
    return nerve::output<T>(p);
  }

  /* Declares number parameter `key` with its default and inclusive bounds
   * (NAN: none); a value outside them is refused by --param and nerve param set. */
  param_f64 param(const char *key, double def, double min = NAN, double max = NAN) {
    nerve_param p = 0;
    detail::check(nerve_setup_param_f64(s_, key, def, min, max, &p), "nerve_setup_param_f64");
    return param_f64(p);
  }

  /* Declares sequence input `name`: a Header (no_header: none) and any
   * number of Elem, each a built-in payload struct or an own type. */
  template <class Elem, class Header = no_header>
  nerve::seq_input<Elem, Header> input_seq(const char *name) {
    nerve_port p = 0;
    nerve_type e = part<Elem>(), h = part<Header>();
    detail::check(nerve_setup_input_seq(s_, name, &e, header_or_null<Header>(h), &p), "nerve_setup_input_seq");
    return nerve::seq_input<Elem, Header>(p);
  }

  /* Declares sequence output `name` of at most `max_len` elements a sample. */
  template <class Elem, class Header = no_header>
  nerve::seq_output<Elem, Header> output_seq(const char *name, std::size_t max_len) {
    nerve_port p = 0;
    nerve_type e = part<Elem>(), h = part<Header>();
    detail::check(nerve_setup_output_seq(s_, name, &e, header_or_null<Header>(h), max_len, &p),
                  "nerve_setup_output_seq");
    return nerve::seq_output<Elem, Header>(p);
  }

  /* Declares service `name`, answered in a step with context::serve. */
  template <class Req, class Resp>
  nerve::server<Req, Resp> serve(const char *name) {
    nerve_port p = 0;
    nerve_type q = part<Req>(), a = part<Resp>();
    detail::check(nerve_setup_serve(s_, name, &q, &a, &p), "nerve_setup_serve");
    return nerve::server<Req, Resp>(p);
  }

  /* Declares client `name` of a service of Req and Resp; each call waits
   * at most `timeout_ns` (0: 2 s) for its answer. */
  template <class Req, class Resp>
  nerve::client<Req, Resp> client(const char *name, std::uint64_t timeout_ns = 0) {
    nerve_port p = 0;
    nerve_type q = part<Req>(), a = part<Resp>();
    detail::check(nerve_setup_client(s_, name, &q, &a, timeout_ns, &p), "nerve_setup_client");
    return nerve::client<Req, Resp>(p);
  }

  /* Declares service `name` answered with sequences of at most `max_len`
   * Elem after a Header, answered in a step with context::serve_seq. */
  template <class Req, class Elem, class Header = no_header>
  nerve::seq_server<Req, Elem, Header> serve_seq(const char *name, std::size_t max_len) {
    nerve_port p = 0;
    nerve_type q = part<Req>(), e = part<Elem>(), h = part<Header>();
    detail::check(nerve_setup_serve_seq(s_, name, &q, &e, header_or_null<Header>(h), max_len, &p),
                  "nerve_setup_serve_seq");
    return nerve::seq_server<Req, Elem, Header>(p);
  }

  /* Declares client `name` of a service of Req answered with sequences;
   * each call waits at most `timeout_ns` (0: the default) for its answer. */
  template <class Req, class Elem, class Header = no_header>
  nerve::seq_client<Req, Elem, Header> client_seq(const char *name, std::uint64_t timeout_ns = 0) {
    nerve_port p = 0;
    nerve_type q = part<Req>(), e = part<Elem>(), h = part<Header>();
    detail::check(nerve_setup_client_seq(s_, name, &q, &e, header_or_null<Header>(h), timeout_ns, &p),
                  "nerve_setup_client_seq");
    return nerve::seq_client<Req, Elem, Header>(p);
  }

  nerve_setup *raw() const noexcept { return s_; }

 private:
  /* T as one part of a sequence or a call: an own type's layout, or a
   * built-in payload by name (no_header: nothing, see header_or_null). */
  template <class T>
  static nerve_type part() {
    if constexpr (std::is_same<T, no_header>::value) {
      return nerve_type{"", 0, 1, nullptr, 0};
    } else if constexpr (detail::is_own<T>::value) {
      static_assert(std::is_trivially_copyable<T>::value, "a payload is a plain struct");
      return *own_layout<T>();
    } else {
      static_assert(std::is_trivially_copyable<T>::value, "a payload is a plain struct");
      return nerve_type{payload<T>::type_name, sizeof(T), alignof(T), nullptr, 0};
    }
  }

  template <class Header>
  static const nerve_type *header_or_null(const nerve_type &h) noexcept {
    return std::is_same<Header, no_header>::value ? nullptr : &h;
  }

  /* Own type T's layout, checked to describe T (not another struct). */
  template <class T>
  static const nerve_type *own_layout() {
    const nerve_type *l = own_type<T>::get();
    if (l->size != sizeof(T) || l->align != alignof(T)) {
      throw error(NERVE_LAYOUT_MISMATCH, std::string("NERVE_HPP_OWN_TYPE: the layout given for ") + l->type_name +
                                             " has size " + std::to_string(l->size) + ", but the C++ struct " +
                                             std::to_string(sizeof(T)) + ": give NERVE_TYPE the struct itself");
    }
    return l;
  }

  nerve_setup *s_;
};

/* A slot of output T's shared memory to write in place, then send(). Not
 * sent, it is given back when the callback returns. */
template <class T>
class loan {
 public:
  T *operator->() const noexcept { return data_; }
  T &operator*() const noexcept { return *data_; }
  /* Publishes the sample; the loan is spent. */
  void send() {
    detail::check(nerve_send(ctx_, port_), "nerve_send");
    data_ = nullptr;
  }

 private:
  friend class context;
  loan(nerve_ctx *c, nerve_port p, T *d) noexcept : ctx_(c), port_(p), data_(d) {}
  nerve_ctx *ctx_;
  nerve_port port_;
  T *data_;
};

/* A received sequence sample, read in place in shared memory until the
 * callback returns: header() and the elements (begin/end, size, []). */
template <class Elem, class Header = no_header>
class seq_view {
 public:
  const Header &header() const noexcept { return *h_; }
  const Elem *begin() const noexcept { return items_; }
  const Elem *end() const noexcept { return items_ + n_; }
  const Elem &operator[](std::size_t i) const noexcept { return items_[i]; }
  std::size_t size() const noexcept { return n_; }
  bool empty() const noexcept { return n_ == 0; }

 private:
  friend class context;
  seq_view(const nerve_seq &s) noexcept
      : h_(static_cast<const Header *>(s.header)), items_(static_cast<const Elem *>(s.items)), n_(s.len) {}
  const Header *h_;
  const Elem *items_;
  std::size_t n_;
};

/* A loaned sequence sample of size() elements to write in place, then
 * send(): the header zeroed, the elements as the slot last held them
 * (write every one). Not sent, it is given back when the callback returns. */
template <class Elem, class Header = no_header>
class seq_loan {
 public:
  Header &header() const noexcept { return *h_; }
  Elem *begin() const noexcept { return items_; }
  Elem *end() const noexcept { return items_ + n_; }
  Elem &operator[](std::size_t i) const noexcept { return items_[i]; }
  std::size_t size() const noexcept { return n_; }
  /* Publishes the sample; the loan is spent. */
  void send() {
    detail::check(nerve_send(ctx_, port_), "nerve_send");
    items_ = nullptr;
    n_ = 0;
  }

 private:
  friend class context;
  seq_loan(nerve_ctx *c, nerve_port p, const nerve_seq_loan &l) noexcept
      : ctx_(c), port_(p), h_(static_cast<Header *>(l.header)), items_(static_cast<Elem *>(l.items)), n_(l.len) {}
  nerve_ctx *ctx_;
  nerve_port port_;
  Header *h_;
  Elem *items_;
  std::size_t n_;
};

/* A sequence answer loaned at size() elements, written in place during
 * the answer function: header() zeroed, the elements zeroed. */
template <class Elem, class Header = no_header>
class seq_answer {
 public:
  Header &header() const noexcept { return *h_; }
  Elem *begin() const noexcept { return items_; }
  Elem *end() const noexcept { return items_ + n_; }
  Elem &operator[](std::size_t i) const noexcept { return items_[i]; }
  std::size_t size() const noexcept { return n_; }

 private:
  template <class, class>
  friend class answer_loan;
  explicit seq_answer(const nerve_seq_loan &l) noexcept
      : h_(static_cast<Header *>(l.header)), items_(static_cast<Elem *>(l.items)), n_(l.len) {}
  Header *h_;
  Elem *items_;
  std::size_t n_;
};

/* The answer to one request of a seq_server, during context::serve_seq's
 * function: loan(n) it at the length it needs. */
template <class Elem, class Header = no_header>
class answer_loan {
 public:
  /* The answer at `n` elements to write in place; empty optional past the
   * service's max_len (nothing loaned: the caller is told its answer was
   * too long). Not loaned at all, the answer is 0 elements, header zeroed. */
  std::optional<seq_answer<Elem, Header>> loan(std::size_t n) {
    nerve_seq_loan l{};
    nerve_status s = nerve_answer_loan(a_, n, &l);
    if (s == NERVE_TOO_LONG) {
      return std::nullopt;
    }
    detail::check(s, "nerve_answer_loan");
    return seq_answer<Elem, Header>(l);
  }

 private:
  friend class context;
  explicit answer_loan(nerve_answer *a) noexcept : a_(a) {}
  nerve_answer *a_;
};

/* A finished call of a client: its id, and its answer or why none came. */
template <class Resp>
struct finished {
  std::uint64_t id = 0;
  std::optional<Resp> answer;
  /* why there is no answer (timed out, server gone, unwired); "" with one */
  std::string error;
};

/* What start, step and stop get; valid during the callback only. */
class context {
 public:
  explicit context(nerve_ctx *c) noexcept : c_(c) {}

  /* The next sample waiting on `in`, in shared memory until the callback
   * returns; nullptr when none waits. */
  template <class T>
  const T *take(const input<T> &in) {
    return sample<T>(nerve_take, in, "nerve_take");
  }

  /* The newest sample waiting on `in` (older ones are dropped); nullptr when none. */
  template <class T>
  const T *latest(const input<T> &in) {
    return sample<T>(nerve_latest, in, "nerve_latest");
  }

  /* A zeroed slot of `out` to write in place, then loan::send(). */
  template <class T>
  nerve::loan<T> loan(const output<T> &out) {
    void *d = nullptr;
    detail::check(nerve_loan(c_, out.handle(), &d), "nerve_loan");
    return nerve::loan<T>(c_, out.handle(), static_cast<T *>(d));
  }

  /* A slot of `out` as it is (not zeroed: what an earlier sample left in
   * it) to write in place, then loan::send(): write every field readers read.
   * A large payload of which only a part is written costs that part. */
  template <class T>
  nerve::loan<T> loan_uninit(const output<T> &out) {
    void *d = nullptr;
    detail::check(nerve_loan_uninit(c_, out.handle(), &d), "nerve_loan_uninit");
    return nerve::loan<T>(c_, out.handle(), static_cast<T *>(d));
  }

  /* Sends a copy of `value` on `out` (a loan, one struct copy, a send). */
  template <class T>
  void send(const output<T> &out, const T &value) {
    nerve::loan<T> l = loan(out);
    *l = value;
    l.send();
  }

  /* Parameter `p`'s current value. */
  double param(const param_f64 &p) {
    double v = 0;
    detail::check(nerve_param_f64(c_, p.handle(), &v), "nerve_param_f64");
    return v;
  }

  /* How many steps ran before this one. */
  std::uint64_t cycle() {
    std::uint64_t n = 0;
    detail::check(nerve_cycle(c_, &n), "nerve_cycle");
    return n;
  }

  /* Stops the agent after this callback. */
  void request_stop() { detail::check(nerve_request_stop(c_), "nerve_request_stop"); }

  /* The next sequence waiting on `in`, in place; empty optional when none waits. */
  template <class Elem, class Header>
  std::optional<seq_view<Elem, Header>> take(const seq_input<Elem, Header> &in) {
    return seq(nerve_take_seq, in, "nerve_take_seq");
  }

  /* The newest sequence waiting on `in` (older ones dropped); empty optional when none. */
  template <class Elem, class Header>
  std::optional<seq_view<Elem, Header>> latest(const seq_input<Elem, Header> &in) {
    return seq(nerve_latest_seq, in, "nerve_latest_seq");
  }

  /* A sample of `n` elements of `out` to write in place, then seq_loan::send();
   * throws nerve::error (NERVE_TOO_LONG) past its max_len, nothing loaned. */
  template <class Elem, class Header>
  seq_loan<Elem, Header> loan(const seq_output<Elem, Header> &out, std::size_t n) {
    nerve_seq_loan l{};
    detail::check(nerve_loan_seq(c_, out.handle(), n, &l), "nerve_loan_seq");
    return seq_loan<Elem, Header>(c_, out.handle(), l);
  }

  /* Answers the requests waiting on `srv` with `f(const Req &) -> Resp`,
   * called here once per request; returns how many. An exception from
   * `f` drops that request unanswered and is thrown on from here. */
  template <class Req, class Resp, class F>
  std::size_t serve(const server<Req, Resp> &srv, F &&f) {
    struct answering {
      F *f;
      std::exception_ptr thrown;
    } c{&f, nullptr};
    auto answer = [](const void *req, void *ans, void *user) -> int {
      answering *k = static_cast<answering *>(user);
      try {
        *static_cast<Resp *>(ans) = (*k->f)(*static_cast<const Req *>(req));
        return 0;
      } catch (...) {
        k->thrown = std::current_exception();
        return 1;
      }
    };
    std::size_t n = 0;
    nerve_status s = nerve_serve(c_, srv.handle(), answer, &c, &n);
    if (c.thrown) {
      std::rethrow_exception(c.thrown);
    }
    detail::check(s, "nerve_serve");
    return n;
  }

  /* Sends `req` on `cl` and returns its call id at once; the answer comes
   * from take_answer in this or a later step. Throws nerve::error
   * (NERVE_CALL_FAILED) when nothing could be sent (not wired, no server,
   * too many in flight). */
  template <class Req, class Resp>
  std::uint64_t call(const client<Req, Resp> &cl, const Req &req) {
    std::uint64_t id = 0;
    detail::check(nerve_call(c_, cl.handle(), &req, sizeof req, &id), "nerve_call");
    return id;
  }

  /* The oldest finished call of `cl` (answered, or why not); empty
   * optional while none has finished. Never blocks. */
  template <class Req, class Resp>
  std::optional<finished<Resp>> take_answer(const client<Req, Resp> &cl) {
    finished<Resp> f;
    Resp r{};
    nerve_status s = nerve_call_take(c_, cl.handle(), &f.id, &r, sizeof r);
    if (s == NERVE_NO_SAMPLE) {
      return std::nullopt;
    }
    if (s == NERVE_CALL_FAILED) {
      f.error = nerve_last_error();
      return f;
    }
    detail::check(s, "nerve_call_take");
    f.answer = r;
    return f;
  }

  /* Answers the requests waiting on `srv` with `f(const Req &,
   * answer_loan<Elem, Header> &)`, called here once per request, which
   * loans the answer and writes it in place; returns how many. An
   * exception from `f` drops that request unanswered and is thrown on from
   * here; an answer refused past max_len throws nerve::error
   * (NERVE_TOO_LONG) once the others are answered. */
  template <class Req, class Elem, class Header, class F>
  std::size_t serve_seq(const seq_server<Req, Elem, Header> &srv, F &&f) {
    struct answering {
      F *f;
      std::exception_ptr thrown;
    } c{&f, nullptr};
    auto answer = [](const void *req, nerve_answer *ans, void *user) -> int {
      answering *k = static_cast<answering *>(user);
      try {
        answer_loan<Elem, Header> loan(ans);
        (*k->f)(*static_cast<const Req *>(req), loan);
        return 0;
      } catch (...) {
        k->thrown = std::current_exception();
        return 1;
      }
    };
    std::size_t n = 0;
    nerve_status s = nerve_serve_seq(c_, srv.handle(), answer, &c, &n);
    if (c.thrown) {
      std::rethrow_exception(c.thrown);
    }
    detail::check(s, "nerve_serve_seq");
    return n;
  }

  /* Sends `req` on the sequence client `cl`, as call does. */
  template <class Req, class Elem, class Header>
  std::uint64_t call(const seq_client<Req, Elem, Header> &cl, const Req &req) {
    std::uint64_t id = 0;
    detail::check(nerve_call(c_, cl.handle(), &req, sizeof req, &id), "nerve_call");
    return id;
  }

  /* The oldest finished call of `cl`: its id, and its answer read in place
   * (valid until the next take_answer on `cl`) or why none came; empty
   * optional while none has finished. Never blocks. */
  template <class Req, class Elem, class Header>
  std::optional<std::pair<std::uint64_t, std::optional<seq_view<Elem, Header>>>> take_answer(
      const seq_client<Req, Elem, Header> &cl, std::string *error = nullptr) {
    std::uint64_t id = 0;
    nerve_seq s{};
    nerve_status st = nerve_call_take_seq(c_, cl.handle(), &id, &s);
    if (st == NERVE_NO_SAMPLE) {
      return std::nullopt;
    }
    if (st == NERVE_CALL_FAILED) {
      if (error != nullptr) {
        *error = nerve_last_error();
      }
      return std::make_pair(id, std::optional<seq_view<Elem, Header>>());
    }
    detail::check(st, "nerve_call_take_seq");
    return std::make_pair(id, std::optional<seq_view<Elem, Header>>(seq_view<Elem, Header>(s)));
  }

  /* Calls and waits in the step for the answer, at most the client's
   * timeout; throws nerve::error (NERVE_CALL_FAILED) without one. */
  template <class Req, class Resp>
  Resp call_wait(const client<Req, Resp> &cl, const Req &req) {
    Resp r{};
    detail::check(nerve_call_wait(c_, cl.handle(), &req, sizeof req, &r, sizeof r), "nerve_call_wait");
    return r;
  }

  nerve_ctx *raw() const noexcept { return c_; }

 private:
  template <class Elem, class Header>
  std::optional<seq_view<Elem, Header>> seq(nerve_status (*f)(nerve_ctx *, nerve_port, nerve_seq *),
                                            const seq_input<Elem, Header> &in, const char *call) {
    nerve_seq s{};
    nerve_status st = f(c_, in.handle(), &s);
    if (st == NERVE_NO_SAMPLE) {
      return std::nullopt;
    }
    detail::check(st, call);
    return seq_view<Elem, Header>(s);
  }

  template <class T>
  const T *sample(nerve_status (*f)(nerve_ctx *, nerve_port, const void **, size_t *), const input<T> &in,
                  const char *call) {
    const void *d = nullptr;
    size_t len = 0;
    nerve_status s = f(c_, in.handle(), &d, &len);
    if (s == NERVE_NO_SAMPLE) {
      return nullptr;
    }
    detail::check(s, call);
    if (len != sizeof(T)) {
      throw error(NERVE_LAYOUT_MISMATCH, std::string(call) + ": a sample of " + std::to_string(len) +
                                             " bytes on a port of " + detail::type_name<T>() + " (" +
                                             std::to_string(sizeof(T)) + " bytes)");
    }
    return static_cast<const T *>(d);
  }

  nerve_ctx *c_;
};

/* A C++ agent: its kind, period and callbacks (lambdas or any callable).
 * run() hands it to the nerve runtime and returns main's exit status. */
class agent {
 public:
  /* `kind` as nerve ps shows it; `period_ns` 0 for an event-driven agent
   * (steps when an input has news), else its period (at least 10000). */
  explicit agent(std::string kind, std::uint64_t period_ns = 0) : kind_(std::move(kind)), period_ns_(period_ns) {}
  agent(const agent &) = delete;
  agent &operator=(const agent &) = delete;

  agent &on_init(std::function<void(setup &)> f) {
    init_ = std::move(f);
    return *this;
  }
  agent &on_start(std::function<void(context &)> f) {
    start_ = std::move(f);
    return *this;
  }
  agent &on_step(std::function<void(context &)> f) {
    step_ = std::move(f);
    return *this;
  }
  agent &on_stop(std::function<void(context &)> f) {
    stop_ = std::move(f);
    return *this;
  }

  /* Runs the agent with main's command line until it stops; call once,
   * from main's thread. Returns the exit status for main. */
  int run(int argc, char **argv) {
    if (!init_ || !step_) {
      std::fprintf(stderr, "%s: nerve::agent needs on_init and on_step before run\n", kind_.c_str());
      return 2;
    }
    nerve_agent_vtable vt = vtable();
    return nerve_run(argc, argv, &vt, this);
  }

 private:
  friend class harness;

  /* The C vtable of this agent; its `user` pointer is `this`. */
  nerve_agent_vtable vtable() const noexcept {
    nerve_agent_vtable vt{};
    vt.kind = kind_.c_str();
    vt.period_ns = period_ns_;
    vt.init = &agent::init_cb;
    vt.start = start_ ? &agent::start_cb : nullptr;
    vt.step = &agent::step_cb;
    vt.stop = stop_ ? &agent::stop_cb : nullptr;
    return vt;
  }

  /* Calls `f`; an exception becomes a message and a failed call (1). */
  template <class F>
  int guarded(const char *what, F &&f) noexcept {
    try {
      f();
      return 0;
    } catch (const std::exception &e) {
      std::fprintf(stderr, "%s: %s: %s\n", kind_.c_str(), what, e.what());
    } catch (...) {
      std::fprintf(stderr, "%s: %s: an exception that is not a std::exception\n", kind_.c_str(), what);
    }
    return 1;
  }

  static int init_cb(nerve_setup *s, void *user) noexcept {
    auto *a = static_cast<agent *>(user);
    return a->guarded("init", [&] {
      setup st(s);
      a->init_(st);
    });
  }
  static int start_cb(nerve_ctx *c, void *user) noexcept {
    auto *a = static_cast<agent *>(user);
    return a->guarded("start", [&] {
      context cx(c);
      a->start_(cx);
    });
  }
  static int step_cb(nerve_ctx *c, void *user) noexcept {
    auto *a = static_cast<agent *>(user);
    return a->guarded("step", [&] {
      context cx(c);
      a->step_(cx);
    });
  }
  static void stop_cb(nerve_ctx *c, void *user) noexcept {
    auto *a = static_cast<agent *>(user);
    a->guarded("stop", [&] {
      context cx(c);
      a->stop_(cx);
    });
  }

  std::string kind_;
  std::uint64_t period_ns_;
  std::function<void(setup &)> init_;
  std::function<void(context &)> start_, step_, stop_;
};

/* A C++ agent in a test (the C test harness, nerve_harness_*): its
 * callbacks run in this process and thread, with no router and no shared
 * memory, on a clock the test moves. RAII: the destructor runs the agent's
 * stop and frees the harness. Every failure throws nerve::error (a step
 * that threw or failed: NERVE_AGENT_FAILED, with the agent's message).
 *
 *   nerve::agent a("scale");
 *   define(a);                               // the agent's on_init, on_step
 *   nerve::harness h(a, {"gain=3"});
 *   h.send("in", nerve_Tick{7, 0});
 *   h.step();
 *   std::optional<nerve_Tick> t = h.output<nerve_Tick>("out");  // seq 21
 *
 * The agent must outlive the harness; one thread at a time uses it. */
class harness {
 public:
  /* Runs `a`'s init (with `params`, "KEY=VALUE" each) and start. */
  explicit harness(agent &a, const std::vector<std::string> &params = {}) {
    if (!a.init_ || !a.step_) {
      throw error(NERVE_INVALID_ARGUMENT, "nerve::harness: the agent needs on_init and on_step");
    }
    std::vector<const char *> p;
    for (const std::string &kv : params) {
      p.push_back(kv.c_str());
    }
    nerve_agent_vtable vt = a.vtable();
    detail::check(nerve_harness_new(&vt, &a, p.data(), p.size(), &h_), "nerve_harness_new");
  }
  harness(const harness &) = delete;
  harness &operator=(const harness &) = delete;
  ~harness() { nerve_harness_free(h_); }

  /* Queues a copy of `value` on input `input`. */
  template <class T>
  void send(const char *input, const T &value) {
    static_assert(std::is_trivially_copyable<T>::value, "a payload is a plain struct");
    detail::check(nerve_harness_send(h_, input, &value, sizeof(T)), "nerve_harness_send");
  }

  /* One cycle (a periodic agent's clock moves to its next deadline). */
  void step() { detail::check(nerve_harness_step(h_), "nerve_harness_step"); }

  /* Moves the clock on by `ns`; returns how many steps ran. */
  std::uint64_t advance(std::uint64_t ns) {
    std::uint64_t steps = 0;
    detail::check(nerve_harness_advance(h_, ns, &steps), "nerve_harness_advance");
    return steps;
  }

  /* The oldest sample `output` sent that the test has not read; empty when none. */
  template <class T>
  std::optional<T> output(const char *output) {
    T value{};
    size_t len = 0;
    nerve_status s = nerve_harness_output(h_, output, &value, sizeof(T), &len);
    if (s == NERVE_NO_SAMPLE) {
      return std::nullopt;
    }
    detail::check(s, "nerve_harness_output");
    return value;
  }

  /* Sets a parameter as `nerve param set` does (refused out of its bounds). */
  void set_param(const char *key, const std::string &value) {
    detail::check(nerve_harness_set_param(h_, key, value.c_str()), "nerve_harness_set_param");
  }

  /* Changes a periodic agent's period, as `nerve rate` does. */
  void set_period(std::uint64_t ns) { detail::check(nerve_harness_set_period(h_, ns), "nerve_harness_set_period"); }

  /* The clock the agent reads (ns; starts at 1 s). */
  std::uint64_t now_ns() {
    std::uint64_t now = 0;
    detail::check(nerve_harness_clock(h_, &now, nullptr), "nerve_harness_clock");
    return now;
  }

  /* How many steps ran. */
  std::uint64_t cycles() {
    std::uint64_t n = 0;
    detail::check(nerve_harness_clock(h_, nullptr, &n), "nerve_harness_clock");
    return n;
  }

  nerve_harness *raw() const noexcept { return h_; }

 private:
  nerve_harness *h_ = nullptr;
};

}  // namespace nerve

#endif /* NERVE_HPP */
