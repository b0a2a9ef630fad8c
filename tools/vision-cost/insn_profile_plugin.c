/* TCG plugin for qemu-user (QEMU 7.2, plugin API version 1): guest instructions per function
 * symbol, counted only inside vision_cost's measured windows (the prctl markers of
 * insn_count_plugin.c). Writes "<instructions> <symbol>" lines, largest first, to out=FILE;
 * blocks of code without a symbol (shared libraries: qemu-user reads only the executable's
 * symbols) are summed as "?". Inlined code counts for the function it was inlined into.
 * Arguments: out=FILE (required), nr=N (prctl's system call number, default 167 = aarch64).
 *
 * Every translated block gets an inline counter of its symbol (no callback, as the count
 * plugin); at each marker every symbol's counter is read, so the totals are window sums. */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef uint64_t qemu_plugin_id_t;
typedef struct qemu_info_t qemu_info_t;
struct qemu_plugin_tb;
struct qemu_plugin_insn;
enum qemu_plugin_op { QEMU_PLUGIN_INLINE_ADD_U64 };
typedef void (*qemu_plugin_vcpu_tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb* tb);
typedef void (*qemu_plugin_vcpu_syscall_cb_t)(qemu_plugin_id_t id, unsigned int vcpu_index,
                                              int64_t num, uint64_t a1, uint64_t a2, uint64_t a3,
                                              uint64_t a4, uint64_t a5, uint64_t a6, uint64_t a7,
                                              uint64_t a8);
typedef void (*qemu_plugin_udata_cb_t)(qemu_plugin_id_t id, void* userdata);
void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t cb);
void qemu_plugin_register_vcpu_syscall_cb(qemu_plugin_id_t id, qemu_plugin_vcpu_syscall_cb_t cb);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, qemu_plugin_udata_cb_t cb, void* udata);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb* tb);
struct qemu_plugin_insn* qemu_plugin_tb_get_insn(const struct qemu_plugin_tb* tb, size_t idx);
const char* qemu_plugin_insn_symbol(const struct qemu_plugin_insn* insn);
void qemu_plugin_register_vcpu_tb_exec_inline(struct qemu_plugin_tb* tb, enum qemu_plugin_op op,
                                              void* ptr, uint64_t imm);

#define EXPORT __attribute__((visibility("default")))
EXPORT int qemu_plugin_version = 1;

static int64_t g_prctl_nr = 167;
#define kMarkerOn 0x41475631u
#define kMarkerOff 0x41475630u
#define kMaxSymbols 65536

struct Sym {
  const char* name; /* NULL: no symbol */
  int used;
  uint64_t count; /* every execution, inline */
  uint64_t at_on; /* count at the last "on" marker */
  uint64_t total; /* sum over the windows */
};
static struct Sym* g_syms;
static int g_open;
static FILE* g_out;

/* A few thousand symbols: open addressing on the name pointer (qemu keeps the strings). */
static struct Sym* sym_of(const char* name) {
  size_t h = ((uintptr_t)name >> 3) % kMaxSymbols;
  for (size_t k = 0; k < kMaxSymbols; ++k, h = (h + 1) % kMaxSymbols) {
    struct Sym* s = &g_syms[h];
    if (s->used && s->name == name) return s;
    if (!s->used) {
      s->used = 1;
      s->name = name;
      return s;
    }
  }
  return NULL;
}

static void on_tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb* tb) {
  (void)id;
  const char* name = qemu_plugin_insn_symbol(qemu_plugin_tb_get_insn(tb, 0));
  struct Sym* s = sym_of(name);
  if (s) {
    qemu_plugin_register_vcpu_tb_exec_inline(tb, QEMU_PLUGIN_INLINE_ADD_U64, &s->count,
                                             qemu_plugin_tb_n_insns(tb));
  }
}

static void on_syscall(qemu_plugin_id_t id, unsigned int vcpu, int64_t num, uint64_t a1,
                       uint64_t a2, uint64_t a3, uint64_t a4, uint64_t a5, uint64_t a6, uint64_t a7,
                       uint64_t a8) {
  (void)id, (void)vcpu, (void)a2, (void)a3, (void)a4, (void)a5, (void)a6, (void)a7, (void)a8;
  if (num != g_prctl_nr) return;
  if (a1 == kMarkerOn) {
    for (size_t i = 0; i < kMaxSymbols; ++i) g_syms[i].at_on = g_syms[i].count;
    g_open = 1;
  } else if (a1 == kMarkerOff && g_open) {
    for (size_t i = 0; i < kMaxSymbols; ++i) g_syms[i].total += g_syms[i].count - g_syms[i].at_on;
    g_open = 0;
  }
}

static int by_total(const void* a, const void* b) {
  const struct Sym* x = a;
  const struct Sym* y = b;
  return x->total < y->total ? 1 : x->total > y->total ? -1 : 0;
}

static void on_exit_cb(qemu_plugin_id_t id, void* udata) {
  (void)id, (void)udata;
  qsort(g_syms, kMaxSymbols, sizeof *g_syms, by_total);
  for (size_t i = 0; i < kMaxSymbols; ++i) {
    const struct Sym* s = &g_syms[i];
    if (s->total == 0) break;
    fprintf(g_out, "%llu %s\n", (unsigned long long)s->total, s->name ? s->name : "?");
  }
  fclose(g_out);
}

EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t* info, int argc,
                               char** argv) {
  (void)info;
  const char* path = NULL;
  for (int i = 0; i < argc; i++) {
    if (strncmp(argv[i], "out=", 4) == 0) path = argv[i] + 4;
    if (strncmp(argv[i], "nr=", 3) == 0) g_prctl_nr = strtoll(argv[i] + 3, NULL, 10);
  }
  if (!path) {
    fprintf(stderr, "insn_profile_plugin: needs out=FILE\n");
    return -1;
  }
  g_out = fopen(path, "w");
  g_syms = calloc(kMaxSymbols, sizeof *g_syms);
  if (!g_out || !g_syms) return -1;
  qemu_plugin_register_vcpu_tb_trans_cb(id, on_tb_trans);
  qemu_plugin_register_vcpu_syscall_cb(id, on_syscall);
  qemu_plugin_register_atexit_cb(id, on_exit_cb, NULL);
  return 0;
}
