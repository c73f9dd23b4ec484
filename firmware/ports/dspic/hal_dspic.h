/*
 * hal_dspic.h - the robot firmware's HAL (firmware/core/include/pfw_hal.h) on the paper's dsPIC30F6014, for XC16.
 *
 * Clock: the internal FRC oscillator (7.37 MHz) through the PLL x16: Fosc = 117.92 MHz, Fcy = Fosc / 4 =
 * 29.48 MIPS (config_dspic.c). FRC with the PLL is a dsPIC30F6014A option; a board with a 7.3728 MHz crystal
 * gets the same Fcy with XT_PLL16 (change FOSFPR in config_dspic.c and, for another crystal, PFW_FCY here).
 * The FRC's accuracy (+-2 % over temperature) is the clock tolerance the PC assumes (docs/protocol.md, section 5).
 *
 * Pin map (80-pin TQFP; confirm against the robot's schematic before flashing):
 *
 *   UART2   U2RX RF4, U2TX RF5   the XBee (DIN <- U2TX, DOUT -> U2RX), 57600 baud 8N1: U2BRG = 31, 57578 baud
 *                                (-0.04 %); UART1 stays free for a bootloader or a debug console
 *   OC1     RD0                  right fin servo: Output Compare 1 in PWM mode on Timer2
 *   OC2     RD1                  left fin servo: Output Compare 2 in PWM mode on Timer2
 *   Timer2  1:64, PR2 = 9211     the servo frame: 29.48 MHz / 64 = 460.6 kHz, 9212 counts = 20.00 ms (50 Hz),
 *                                2.17 us per count (0.33 deg of fin at the calibration below)
 *   Timer1  1:1, PR1 = 29479     the 1 ms clock (interrupt)
 *   Timer3  1:1, free-running    entropy: counts Fcy cycles during ADC conversions clocked by the ADC's own RC
 *   AN15    RB15, unconnected    entropy: ADC noise of a floating input (any free analog pin will do)
 *   RD2     output               probe: high while pfw_app_step runs (a logic analyser measures the step)
 */
#ifndef HAL_DSPIC_H
#define HAL_DSPIC_H

#include <stdint.h>

#include "pfw_hal.h"

#ifndef PFW_FCY
#define PFW_FCY 29480000UL /* instruction cycles per second: 7.37 MHz FRC x PLL16 / 4 */
#endif

/* Servo calibration, as the AVR port's: a fin angle of 90 deg is 1500 us, 1200 us span 0..180 deg (Hitec digital
 * servos' 900..2100 us travel; the linkage's calibration, per robot: measure it). */
#ifndef SERVO_CENTRE_US
#define SERVO_CENTRE_US 1500.0f
#endif
#ifndef SERVO_US_PER_RAD
#define SERVO_US_PER_RAD 381.97186f /* 1200 us / pi rad */
#endif
#define SERVO_PULSE_MIN_US 900u
#define SERVO_PULSE_MAX_US 2100u

#define DSPIC_UART_BAUD 57600UL
#define DSPIC_U2BRG ((PFW_FCY + 8UL * DSPIC_UART_BAUD) / (16UL * DSPIC_UART_BAUD) - 1UL) /* rounded: 31 */
#define DSPIC_PR1 (PFW_FCY / 1000UL - 1UL)                                              /* 29479 */
#define DSPIC_SERVO_TIMER_HZ (PFW_FCY / 64UL)                                           /* 460625 */
#define DSPIC_PR2 (DSPIC_SERVO_TIMER_HZ / 50UL - 1UL)                                   /* 9211 */

/* Set up clock, UART, servos (both at 90 deg), the probe, the boot id; enables the interrupts. Fills *hal. */
void hal_dspic_init(pfw_hal *hal);

/* Sleep until the next interrupt (Idle mode: the peripherals run on). */
void hal_dspic_idle(void);

/* Restart the watchdog (enabled by the configuration bits: a hung main loop resets the chip). */
void hal_dspic_kick(void);

/* Timer2 counts [1 / DSPIC_SERVO_TIMER_HZ] of the pulse for a fin angle [rad], clamped to the servo's range. */
uint16_t hal_dspic_pulse_counts(float angle_rad);

/* Bytes lost to a full ring or a hardware overrun (the main loop fell behind the XBee). */
uint16_t hal_dspic_rx_overflows(void);

#endif /* HAL_DSPIC_H */
