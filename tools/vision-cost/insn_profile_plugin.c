/* TCG plugin for qemu-user (QEMU 7.2, plugin API version 1): guest instructions per function
 * symbol, counted only inside vision_cost's measured windows (the prctl markers of
 * insn_count_plugin.c). Writes "<instructions> <symbol>" lines, largest first, to out=FILE;
 * blocks of code without a symbol (shared libraries: qemu-user reads only the executable's
 * symbols) are summed as "?". Inlined code counts for the function it was inlined into.
 * Arguments: out=FILE (required), nr=N (prctl's system call number, default 167 = aarch64).
 *
 * Every translated block gets an inline counter of its symbol (no callback, as the count
 * plugin); at each marker every symbol's counter is read, so the totals are window sums. */
#include "qemu_plugin.h"

#define kMaxSymbols 65536

struct Sym {
  const char* name; /* NULL: no symbol */
  int used;
  uint64_t count; /* every execution, inline */
  uint64_t at_on; /* count at the last "on" marker */
  uint64_t total; /* sum over the windows */
};
static struct Sym* g_syms;
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

static void plugin_window_open(void) {
  for (size_t i = 0; i < kMaxSymbols; ++i) g_syms[i].at_on = g_syms[i].count;
}

static void plugin_window_close(void) {
  for (size_t i = 0; i < kMaxSymbols; ++i) g_syms[i].total += g_syms[i].count - g_syms[i].at_on;
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
  g_out = plugin_open_output(argc, argv, "insn_profile_plugin");
  g_syms = calloc(kMaxSymbols, sizeof *g_syms);
  if (!g_out || !g_syms) return -1;
  plugin_register(id, on_tb_trans, on_exit_cb);
  return 0;
}
