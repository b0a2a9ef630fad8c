/* TCG plugin for qemu-user (QEMU 7.2, plugin API version 1): counts the guest instructions
 * executed between marker system calls made by vision_cost (prctl with the option values
 * below, which the kernel rejects with EINVAL). Every on->off window is one frame; the plugin
 * writes one line per window ("<instructions>") to the file given as out=FILE.
 * Arguments: out=FILE (required), nr=N (prctl's system call number, default 167 = aarch64).
 *
 * Counting is per translated block: each executed block adds its instruction count (inline,
 * no callback), as QEMU's contrib/plugins/insn.c does in its inline mode. A block always ends at
 * a system call, so window boundaries are exact. The counter is one global: vision_cost runs
 * single-threaded (cv::setNumThreads(0)).
 * Build: see tools/vision-cost/measure.sh. */
#include "qemu_plugin.h"

static uint64_t g_insns; /* all guest instructions executed so far */
static uint64_t g_start; /* g_insns at the last "on" marker */
static FILE* g_out;
static uint64_t g_windows;

static void on_tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb* tb) {
  (void)id;
  qemu_plugin_register_vcpu_tb_exec_inline(tb, QEMU_PLUGIN_INLINE_ADD_U64, &g_insns,
                                           qemu_plugin_tb_n_insns(tb));
}

static void plugin_window_open(void) { g_start = g_insns; }

static void plugin_window_close(void) {
  fprintf(g_out, "%llu\n", (unsigned long long)(g_insns - g_start));
  g_windows++;
}

static void on_exit_cb(qemu_plugin_id_t id, void* udata) {
  (void)id, (void)udata;
  fprintf(stderr, "insn_count_plugin: %llu windows, %llu instructions in total\n",
          (unsigned long long)g_windows, (unsigned long long)g_insns);
  fclose(g_out);
}

EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t* info, int argc,
                               char** argv) {
  (void)info;
  g_out = plugin_open_output(argc, argv, "insn_count_plugin");
  if (!g_out) return -1;
  plugin_register(id, on_tb_trans, on_exit_cb);
  return 0;
}
