/* The C library functions a freestanding build still needs: compilers emit calls to memcpy and
 * memset for structure copies and zeroing (the board's init does both), and the portable code uses
 * them from <string.h>. Plain byte loops: the board copies a few dozen bytes at a time. */
#include <stddef.h>

void *memcpy(void *dst, const void *src, size_t n);
void *memset(void *dst, int value, size_t n);

void *memcpy(void *dst, const void *src, size_t n)
{
    unsigned char *d = dst;
    const unsigned char *s = src;
    while (n--) {
        *d++ = *s++;
    }
    return dst;
}

void *memset(void *dst, int value, size_t n)
{
    unsigned char *d = dst;
    while (n--) {
        *d++ = (unsigned char)value;
    }
    return dst;
}

/* The ARM EABI's names for the same (the run-time ABI for the Arm architecture, section 4.3.4):
 * clang emits these for structure copies and zeroing on Arm targets. */
void __aeabi_memcpy(void *dst, const void *src, size_t n);
void __aeabi_memcpy4(void *dst, const void *src, size_t n);
void __aeabi_memcpy8(void *dst, const void *src, size_t n);
void __aeabi_memclr(void *dst, size_t n);
void __aeabi_memclr4(void *dst, size_t n);
void __aeabi_memclr8(void *dst, size_t n);
void __aeabi_memset(void *dst, size_t n, int value);

void __aeabi_memcpy(void *dst, const void *src, size_t n) { (void)memcpy(dst, src, n); }
void __aeabi_memcpy4(void *dst, const void *src, size_t n) { (void)memcpy(dst, src, n); }
void __aeabi_memcpy8(void *dst, const void *src, size_t n) { (void)memcpy(dst, src, n); }
void __aeabi_memclr(void *dst, size_t n) { (void)memset(dst, 0, n); }
void __aeabi_memclr4(void *dst, size_t n) { (void)memset(dst, 0, n); }
void __aeabi_memclr8(void *dst, size_t n) { (void)memset(dst, 0, n); }
void __aeabi_memset(void *dst, size_t n, int value) { (void)memset(dst, value, n); }
