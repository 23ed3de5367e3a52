/* A CLOCK_MONOTONIC timer whose expiry an event loop can wait on: Linux timerfd (Python 3.11 has no
 * os.timerfd_create). The one part of the core that makes system calls: it owns no memory and holds
 * no state, the caller owns the descriptor (servobus/core/timer.py). Elsewhere every call reports
 * SB_E_UNSUPPORTED and the pacer falls back to yielding until its deadline. */
#if defined(__linux__) && !defined(_GNU_SOURCE)
#define _GNU_SOURCE /* TFD_* flags with -std=c11 */
#endif
#include "sb_internal.h"

#include <errno.h>

#ifdef __linux__
#include <sys/timerfd.h>
#include <time.h>
#include <unistd.h>

static int fail(int *err)
{
    if (err != NULL) {
        *err = errno;
    }
    return SB_E_OS;
}

int sb_timer_open(int *err)
{
    int fd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    return fd >= 0 ? fd : fail(err);
}

int sb_timer_arm(int fd, int64_t deadline_ns, int *err)
{
    if (fd < 0 || deadline_ns < 0) {
        return SB_E_ARG;
    }
    struct itimerspec spec = {0};
    if (deadline_ns == 0) {
        /* it_value 0 would disarm: the earliest instant that still counts as armed (long past) */
        spec.it_value.tv_nsec = 1;
    } else {
        spec.it_value.tv_sec = (time_t)(deadline_ns / 1000000000);
        spec.it_value.tv_nsec = (long)(deadline_ns % 1000000000);
    }
    return timerfd_settime(fd, TFD_TIMER_ABSTIME, &spec, NULL) == 0 ? SB_OK : fail(err);
}

int sb_timer_disarm(int fd, int *err)
{
    if (fd < 0) {
        return SB_E_ARG;
    }
    struct itimerspec spec = {0};
    return timerfd_settime(fd, 0, &spec, NULL) == 0 ? SB_OK : fail(err);
}

int64_t sb_timer_clear(int fd, int *err)
{
    if (fd < 0) {
        return SB_E_ARG;
    }
    uint64_t expirations = 0;
    ssize_t got;
    do {
        got = read(fd, &expirations, sizeof expirations);
    } while (got < 0 && errno == EINTR);
    if (got == (ssize_t)sizeof expirations) {
        return (int64_t)(expirations > INT64_MAX ? INT64_MAX : expirations);
    }
    if (got < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
        return 0; /* not expired yet (or already cleared) */
    }
    if (got >= 0) {
        errno = EIO; /* a short read: never happens on a timerfd */
    }
    return fail(err);
}

int64_t sb_timer_now_ns(void)
{
    struct timespec now;
    if (clock_gettime(CLOCK_MONOTONIC, &now) != 0) {
        return SB_E_OS;
    }
    return (int64_t)now.tv_sec * 1000000000 + now.tv_nsec;
}

#else /* not Linux: no timerfd */

int sb_timer_open(int *err)
{
    if (err != NULL) {
        *err = 0;
    }
    return SB_E_UNSUPPORTED;
}

int sb_timer_arm(int fd, int64_t deadline_ns, int *err)
{
    (void)fd;
    (void)deadline_ns;
    (void)err;
    return SB_E_UNSUPPORTED;
}

int sb_timer_disarm(int fd, int *err)
{
    (void)fd;
    (void)err;
    return SB_E_UNSUPPORTED;
}

int64_t sb_timer_clear(int fd, int *err)
{
    (void)fd;
    (void)err;
    return SB_E_UNSUPPORTED;
}

int64_t sb_timer_now_ns(void)
{
    return SB_E_UNSUPPORTED;
}
#endif
