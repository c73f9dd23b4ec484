/* The boot id from a board's entropy (see boot_id.h). Portable C99, no floating point. */
#include "boot_id.h"

/* MurmurHash3's 32-bit finaliser: a bijection of 32-bit words with full avalanche. */
static uint32_t fmix32(uint32_t h)
{
    h ^= h >> 16;
    h *= 0x85EBCA6Bu;
    h ^= h >> 13;
    h *= 0xC2B2AE35u;
    h ^= h >> 16;
    return h;
}

uint32_t boot_id_mix(uint32_t counter, const uint16_t *samples, size_t n)
{
    uint32_t noise = 0x243F6A88u; /* any constant: the digits of pi */
    uint32_t id;
    for (size_t i = 0; i < n; i++)
        noise = fmix32(noise ^ samples[i]) + (uint32_t)i;
    /* For fixed noise, counter -> id is a bijection (xor then a bijection): consecutive power-ups differ. */
    id = fmix32(counter ^ noise);
    return id ? id : 1u; /* 0 means "no boot" on the wire; fmix32 maps exactly one word to 0 */
}
