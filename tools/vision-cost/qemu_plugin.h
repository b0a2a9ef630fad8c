/* What the two TCG plugins for qemu-user (QEMU 7.2, plugin API version 1) share: the API
 * declarations they use, vision_cost's prctl markers, and the argument handling.
 *
 * Debian's qemu-user ships the plugin loader (-plugin) but neither the example plugins nor the
 * header, so the few API declarations used here are written out below (stable C ABI of
 * include/qemu/qemu-plugin.h, version 1). Each plugin is its own shared object and includes this
 * once. Arguments: out=FILE (required), nr=N (prctl's system call number, default 167 = aarch64).
 */
#ifndef AGV_VISION_COST_QEMU_PLUGIN_H
#define AGV_VISION_COST_QEMU_PLUGIN_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef uint64_t qemu_plugin_id_t;
typedef struct qemu_info_t qemu_info_t; /* opaque here */
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

/* __NR_prctl of the guest: 167 on aarch64 (default); 157 on x86-64 (argument nr=157), used to
 * check the method against callgrind on the same x86-64 binary. */
static int64_t g_prctl_nr = 167;
#define kMarkerOn 0x41475631u  /* "AGV1": start of a measured frame */
#define kMarkerOff 0x41475630u /* "AGV0": end of a measured frame */

/* Reads out=FILE and nr=N, and opens FILE for writing; NULL (with a message naming `plugin`)
 * when out= is missing or the file cannot be opened. */
static FILE* plugin_open_output(int argc, char** argv, const char* plugin) {
  const char* path = NULL;
  for (int i = 0; i < argc; i++) {
    if (strncmp(argv[i], "out=", 4) == 0) path = argv[i] + 4;
    if (strncmp(argv[i], "nr=", 3) == 0) g_prctl_nr = strtoll(argv[i] + 3, NULL, 10);
  }
  if (!path) {
    fprintf(stderr, "%s: needs out=FILE\n", plugin);
    return NULL;
  }
  FILE* out = fopen(path, "w");
  if (!out) perror(path);
  return out;
}

/* Each plugin's work at the start and at the end of a measured window. */
static void plugin_window_open(void);
static void plugin_window_close(void);

static int g_open; /* inside a window */

static void plugin_on_syscall(qemu_plugin_id_t id, unsigned int vcpu, int64_t num, uint64_t a1,
                              uint64_t a2, uint64_t a3, uint64_t a4, uint64_t a5, uint64_t a6,
                              uint64_t a7, uint64_t a8) {
  (void)id, (void)vcpu, (void)a2, (void)a3, (void)a4, (void)a5, (void)a6, (void)a7, (void)a8;
  if (num != g_prctl_nr) return;
  if (a1 == kMarkerOn) {
    plugin_window_open();
    g_open = 1;
  } else if (a1 == kMarkerOff && g_open) {
    plugin_window_close();
    g_open = 0;
  }
}

/* Both plugins count per translated block, watch the markers and write their file at exit. */
static void plugin_register(qemu_plugin_id_t id, qemu_plugin_vcpu_tb_trans_cb_t on_tb_trans,
                            qemu_plugin_udata_cb_t on_exit) {
  qemu_plugin_register_vcpu_tb_trans_cb(id, on_tb_trans);
  qemu_plugin_register_vcpu_syscall_cb(id, plugin_on_syscall);
  qemu_plugin_register_atexit_cb(id, on_exit, NULL);
}

#endif
