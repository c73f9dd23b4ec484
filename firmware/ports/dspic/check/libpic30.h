/* libpic30.h - a host stand-in for XC16's data-EEPROM helpers, for `make -C firmware dspic-check` only.
 * A "program address" is the host address of the eedata variable; check_dspic.c implements the helpers on it. */
#ifndef PFW_STUB_LIBPIC30_H
#define PFW_STUB_LIBPIC30_H

#include <stddef.h>
#include <stdint.h>

#define PFW_EEDATA /* no eedata space on the host: a plain array */
#define _EE_WORD 2
#define _EE_ROW 32

typedef uintptr_t _prog_addressT;
#define _init_prog_address(a, b) ((a) = (_prog_addressT)(b))

void _memcpy_p2d16(void *dest, _prog_addressT src, unsigned int len);
void _erase_eedata(_prog_addressT dst, int len);
void _write_eedata_word(_prog_addressT dst, int dat);
void _wait_eedata(void);

#endif
