/*
 * The boot id from a board's entropy (docs/protocol.md, section 5: random, nonzero, new at every power-up).
 *
 * A port gathers what it has: a power-up counter kept in non-volatile memory (guarantees that consecutive
 * power-ups differ even if every noise source failed) and noisy samples (ADC readings of a floating or noisy
 * input, the count of a timer clocked by one oscillator over a period of another). boot_id_mix() folds them
 * into one 32-bit word through a bijective finaliser, so with the samples unchanged two counters never give
 * the same id, and any sample's change spreads over all 32 bits.
 */
#ifndef PFW_BOOT_ID_H
#define PFW_BOOT_ID_H

#include <stddef.h>
#include <stdint.h>

/* The boot id for power-up number `counter` and `n` noisy 16-bit samples; never 0. */
uint32_t boot_id_mix(uint32_t counter, const uint16_t *samples, size_t n);

#endif
