/* Status names, messages, exit codes, logging and the interrupt flag. */
#include "bounce/status.h"
#include "base/internal.h"

#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

const char *bn_status_name(bn_status s)
{
    switch (s) {
#define BN__CASE(name, code, desc) case BN_##name: return #name;
        BN_STATUS_MAP(BN__CASE)
#undef BN__CASE
    default: return "UNKNOWN";
    }
}

const char *bn_status_str(bn_status s)
{
    switch (s) {
#define BN__CASE(name, code, desc) case BN_##name: return desc;
        BN_STATUS_MAP(BN__CASE)
#undef BN__CASE
    default: return "unknown status";
    }
}

int bn_status_exit_code(bn_status s)
{
    switch (s) {
#define BN__CASE(name, code, desc) case BN_##name: return code;
        BN_STATUS_MAP(BN__CASE)
#undef BN__CASE
    default: return 1;
    }
}

void bn_error_clear(bn_error *err)
{
    if (err) {
        err->status = BN_OK;
        err->msg[0] = '\0';
    }
}

bn_status bn_error_set(bn_error *err, bn_status s, const char *fmt, ...)
{
    if (err) {   /* through a buffer of its own: the arguments may include err->msg (wrapping a message) */
        char buf[sizeof err->msg];
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(buf, sizeof buf, fmt, ap);
        va_end(ap);
        memcpy(err->msg, buf, sizeof buf);
        err->status = s;
    }
    return s;
}

#define BN__WARNING_NAME(id, name) name,
static const char *const bn__warning_names[] = {BN_WARNING_MAP(BN__WARNING_NAME)};

const char *bn_warning_name(bn_warning w) { return (unsigned)w < BN_WARNING_COUNT ? bn__warning_names[w] : "?"; }

static void bn__log_emit(const bn_log *log, const bn_message *m)
{
    if (log && log->fn)
        log->fn(log->user, m);
    else if (m->level == BN_LOG_WARN)
        fprintf(stderr, "bounce: warning: %s [%s]\n", m->text, bn_warning_name(m->code));
    else if (m->level == BN_LOG_INFO && log)
        fprintf(stderr, "bounce: %s\n", m->text);
}

void bn_logf(const bn_log *log, bn_log_level level, const char *fmt, ...)
{
    char buf[2048];
    va_list ap;
    if (log && log->quiet && level != BN_LOG_WARN)
        return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    bn__log_emit(log, &(bn_message){level, BN_W_NONE, NAN, buf});
}

void bn_warnf(const bn_log *log, bn_warning code, double value, const char *fmt, ...)
{
    char buf[2048];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    bn__log_emit(log, &(bn_message){BN_LOG_WARN, code, value, buf});
}

const char *bn_version(void) { return BN_VERSION_STRING; }

static volatile sig_atomic_t bn__interrupt_status = 0;

void bn_interrupt_raise(bn_status s) { bn__interrupt_status = (sig_atomic_t)s; }

bn_status bn_interrupted(void) { return (bn_status)bn__interrupt_status; }
