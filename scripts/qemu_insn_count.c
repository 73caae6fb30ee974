/*
 * A QEMU TCG plugin that counts the guest instructions a program executes under qemu-user, for
 * scripts/instr_count.sh (method: docs/deploy-arm.md). Debian's qemu-user is built with plugin
 * support but ships neither the example plugins nor the plugin header, so this file declares
 * the few stable entry points of QEMU's public plugin API it uses (present, with these
 * signatures, from QEMU 4.2 to 10.x) instead of including <qemu-plugin.h>.
 *
 * Counting: at translation, each translation block (TB) gets an execution callback carrying its
 * instruction count; the callback adds it to one atomic total (guest threads are vCPUs that may
 * run concurrently). A TB left early by a fault or a syscall that does not return still counts
 * whole: negligible for the programs measured here. The total is printed at exit as
 * "insn_count: N" on QEMU's log (-d plugin -D FILE).
 *
 * Build: cc -O2 -shared -fPIC -o libinsn_count.so qemu_insn_count.c
 */
#include <inttypes.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

typedef uint64_t qemu_plugin_id_t;
struct qemu_plugin_tb;
typedef struct qemu_info_t qemu_info_t;
enum qemu_plugin_cb_flags { QEMU_PLUGIN_CB_NO_REGS = 0 };

typedef void (*tb_trans_cb_t)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);
typedef void (*vcpu_udata_cb_t)(unsigned int vcpu_index, void *userdata);
typedef void (*udata_cb_t)(qemu_plugin_id_t id, void *userdata);

extern void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, tb_trans_cb_t cb);
extern void qemu_plugin_register_vcpu_tb_exec_cb(struct qemu_plugin_tb *tb, vcpu_udata_cb_t cb,
                                                 enum qemu_plugin_cb_flags flags, void *userdata);
extern size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
extern void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, udata_cb_t cb, void *userdata);
extern void qemu_plugin_outs(const char *string);

/* API version 1: accepted by QEMU 7.x and later (they accept versions MIN..CURRENT). */
__attribute__((visibility("default"))) int qemu_plugin_version = 1;

static uint64_t total;

static void on_tb_exec(unsigned int vcpu_index, void *n_insns)
{
    (void)vcpu_index;
    __atomic_fetch_add(&total, (uint64_t)(uintptr_t)n_insns, __ATOMIC_RELAXED);
}

static void on_tb_trans(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    qemu_plugin_register_vcpu_tb_exec_cb(tb, on_tb_exec, QEMU_PLUGIN_CB_NO_REGS,
                                         (void *)(uintptr_t)n);
}

static void on_exit(qemu_plugin_id_t id, void *userdata)
{
    (void)id;
    (void)userdata;
    char line[64];
    snprintf(line, sizeof line, "insn_count: %" PRIu64 "\n",
             __atomic_load_n(&total, __ATOMIC_RELAXED));
    qemu_plugin_outs(line);
}

__attribute__((visibility("default"))) int qemu_plugin_install(qemu_plugin_id_t id,
                                                               const qemu_info_t *info,
                                                               int argc, char **argv)
{
    (void)info;
    (void)argc;
    (void)argv;
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_tb_trans);
    qemu_plugin_register_atexit_cb(id, on_exit, NULL);
    return 0;
}
