/*
 * LD_PRELOAD shim for the User-Mode Linux kernel (linux.uml): lets UML 6.1 restore a
 * guest process's FPU registers on a host whose XSAVE area is larger than UML's buffer.
 *
 * UML keeps each guest thread's FPU state in a buffer of sizeof(struct _xstate) = 832
 * bytes (x87, SSE, AVX) and writes it back with PTRACE_SETREGSET(NT_X86_XSTATE). The host
 * kernel accepts that write only with the whole standard-format XSAVE area of the host
 * (x86 xstateregs_set: count must equal the user XSAVE size, else EFAULT). With AVX-512
 * the area is 2.7 KiB, with AMX 11 KiB: every write fails and UML panics at the guest's
 * first system call ("userspace - ptrace set fp regs failed, errno = 14"). Later UML
 * kernels size the buffer from the host; this shim does it for the packaged 6.1.
 *
 * On such a write it reads the target's whole area, overlays the bytes UML gives and
 * writes the whole area back. The state beyond UML's bytes (AVX-512, AMX) is then the
 * host process's current one, not the guest thread's own: guest code must not use it, so
 * the harness runs guest programs with glibc's AVX-512 paths off (GLIBC_TUNABLES); Rust
 * code built for the baseline x86-64 uses SSE only. Reads and every other request pass
 * through untouched; where UML's buffer already fits, the write does too.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <elf.h>
#include <errno.h>
#include <stdarg.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>

typedef long (*ptrace_fn)(int, ...);

/* Larger than any XSAVE area x86 defines today (AMX: 11008 bytes). */
static unsigned char whole[65536] __attribute__((aligned(64)));
/* The host's XSAVE area size, learnt from the first read; 0 until then. */
static size_t host_size;
static int busy;

static ptrace_fn real_ptrace(void)
{
    static ptrace_fn real;
    if (!real)
        real = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");
    return real;
}

static long set_whole_xstate(ptrace_fn real, pid_t pid, void *addr, const struct iovec *iov)
{
    struct iovec w = {whole, sizeof whole};
    long r = real(PTRACE_GETREGSET, pid, addr, &w);
    if (r < 0)
        return r;
    host_size = w.iov_len;
    if (iov->iov_len >= host_size)
        return real(PTRACE_SETREGSET, pid, addr, iov);
    memcpy(whole, iov->iov_base, iov->iov_len);
    w.iov_len = host_size;
    return real(PTRACE_SETREGSET, pid, addr, &w);
}

long ptrace(enum __ptrace_request request, ...)
{
    va_list ap;
    va_start(ap, request);
    pid_t pid = va_arg(ap, pid_t);
    void *addr = va_arg(ap, void *);
    void *data = va_arg(ap, void *);
    va_end(ap);
    ptrace_fn real = real_ptrace();
    if (!real) {
        errno = ENOSYS;
        return -1;
    }
    const struct iovec *iov = data;
    if (request == PTRACE_SETREGSET && (long)addr == NT_X86_XSTATE && iov &&
        (host_size == 0 || iov->iov_len < host_size)) {
        /* One buffer: UML's ptrace calls come from its kernel thread; guard anyway. */
        while (__atomic_exchange_n(&busy, 1, __ATOMIC_ACQUIRE))
            ;
        long r = set_whole_xstate(real, pid, addr, iov);
        int saved = errno;
        __atomic_store_n(&busy, 0, __ATOMIC_RELEASE);
        errno = saved;
        return r;
    }
    return real(request, pid, addr, data);
}
