/*
 * config_dspic.c - the dsPIC30F6014's configuration bits (XC16 #pragma config; MPLAB X's "Configuration Bits"
 * window generates the same lines). Setting names as XC16 gives them for the dsPIC30F6014A: check them against
 * the generator for the robot's exact part before the first build.
 *
 *   FOSFPR  = FRC_PLL16      internal FRC 7.37 MHz x 16 = 117.92 MHz, Fcy = 29.48 MIPS (hal_dspic.h: PFW_FCY);
 *                            with a 7.3728 MHz crystal instead: XT_PLL16 (same Fcy)
 *   FCKSMEN = CSW_FSCM_OFF   no clock switching, no fail-safe clock monitor
 *   WDT     = WDT_ON         the watchdog resets a hung main loop (the loop clears it every pass, ~1 ms)
 *   FWPSA/B = 1:8 / 1:8      timeout 2 ms x 8 x 8 = 128 ms nominal (LPRC 512 kHz: +-20 % or so, still far above
 *                            the longest step)
 *   BOREN   = PBOR_ON        brown-out reset: a sagging servo supply resets the chip instead of corrupting it
 *   MCLRE   = MCLR_EN        the reset pin works (the PICkit needs it)
 *   GWRP, GCP = off          code not write- or read-protected (a research robot: reflash at will)
 */
#ifndef PFW_HOST_CHECK
#pragma config FOSFPR = FRC_PLL16
#pragma config FCKSMEN = CSW_FSCM_OFF
#pragma config FWPSB = WDTPSB_8
#pragma config FWPSA = WDTPSA_8
#pragma config WDT = WDT_ON
#pragma config FPWRT = PWRT_64
#pragma config BORV = BORV27
#pragma config BOREN = PBOR_ON
#pragma config MCLRE = MCLR_EN
#pragma config GWRP = GWRP_OFF
#pragma config GCP = GSS_OFF
#endif

/* ISO C forbids an empty translation unit (-pedantic) when the pragmas are compiled out. */
typedef int pfw_config_bits_unit;
