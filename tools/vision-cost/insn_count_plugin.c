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
 *
 * Debian's qemu-user ships the plugin loader (-plugin) but neither the example plugins nor the
 * header, so the few API declarations used here are written out below (stable C ABI of
 * include/qemu/qemu-plugin.h, version 1). Build: see tools/vision-cost/measure.sh. */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef uint64_t qemu_plugin_id_t;
typedef struct qemu_info_t qemu_info_t; /* opaque here */
struct qemu_plugin_tb;
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
void qemu_plugin_register_vcpu_tb_exec_inline(struct qemu_plugin_tb* tb, enum qemu_plugin_op op,
                                              void* ptr, uint64_t imm);

#define EXPORT __attribute__((visibility("default")))
EXPORT int qemu_plugin_version = 1;

/* __NR_prctl of the guest: 167 on aarch64 (default); 157 on x86-64 (argument nr=157), used to
 * check the method against callgrind on the same x86-64 binary. */
static int64_t g_prctl_nr = 167;
#define kMarkerOn 0x41475631u  /* "AGV1": start of a measured frame */
#define kMarkerOff 0x41475630u /* "AGV0": end of a measured frame */

static uint64_t g_insns; /* all guest instructions executed so far */
static uint64_t g_start; /* g_insns at the last "on" marker */
static int g_open;       /* inside a window */
static FILE* g_out;
static uint64_t g_windows;

static void on_tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb* tb) {
  (void)id;
  qemu_plugin_register_vcpu_tb_exec_inline(tb, QEMU_PLUGIN_INLINE_ADD_U64, &g_insns,
                                           qemu_plugin_tb_n_insns(tb));
}

static void on_syscall(qemu_plugin_id_t id, unsigned int vcpu, int64_t num, uint64_t a1,
                       uint64_t a2, uint64_t a3, uint64_t a4, uint64_t a5, uint64_t a6, uint64_t a7,
                       uint64_t a8) {
  (void)id, (void)vcpu, (void)a2, (void)a3, (void)a4, (void)a5, (void)a6, (void)a7, (void)a8;
  if (num != g_prctl_nr) return;
  if (a1 == kMarkerOn) {
    g_start = g_insns;
    g_open = 1;
  } else if (a1 == kMarkerOff && g_open) {
    fprintf(g_out, "%llu\n", (unsigned long long)(g_insns - g_start));
    g_open = 0;
    g_windows++;
  }
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
  const char* path = NULL;
  for (int i = 0; i < argc; i++) {
    if (strncmp(argv[i], "out=", 4) == 0) path = argv[i] + 4;
    if (strncmp(argv[i], "nr=", 3) == 0) g_prctl_nr = strtoll(argv[i] + 3, NULL, 10);
  }
  if (!path) {
    fprintf(stderr, "insn_count_plugin: needs out=FILE\n");
    return -1;
  }
  g_out = fopen(path, "w");
  if (!g_out) {
    perror(path);
    return -1;
  }
  qemu_plugin_register_vcpu_tb_trans_cb(id, on_tb_trans);
  qemu_plugin_register_vcpu_syscall_cb(id, on_syscall);
  qemu_plugin_register_atexit_cb(id, on_exit_cb, NULL);
  return 0;
}
