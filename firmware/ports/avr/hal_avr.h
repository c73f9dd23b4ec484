/*
 * hal_avr.h - the robot firmware's HAL (firmware/core/include/pfw_hal.h) on an ATmega2560 at 16 MHz.
 *
 * The ATmega2560 stands in for the robot's dsPIC30F6014 in an instruction-level simulator (simavr): the same
 * 8 KB of RAM, no FPU, 32-bit float (avr-gcc's double is 32-bit too). Pin map (Arduino Mega 2560 names):
 *
 *   USART0  RXD0 PE0 (D0), TXD0 PE1 (D1)   the XBee, 57600 baud 8N1 (UBRR0 = 34 with U2X0: 57143 baud, -0.8 %)
 *   OC1A    PB5 (D11)                     right fin servo, 50 Hz (Timer1 fast PWM, TOP = ICR1, 0.5 us steps)
 *   OC1B    PB6 (D12)                     left fin servo
 *   Timer0  compare A                     the 1 ms clock (CTC, 16 MHz / 64 / 250)
 *   ADC0    PF0 (A0), left floating       noise for the boot id
 *   PA0     (D22)                         probe: high while pfw_app_step runs (a logic analyser, or the
 *                                         simulator harness, measures the step's length)
 *   PA1     (D23)                         probe: high while a measured section runs (timing build)
 */
#ifndef HAL_AVR_H
#define HAL_AVR_H

#include <stdint.h>

#include "pfw_hal.h"

#ifndef F_CPU
#define F_CPU 16000000UL
#endif

/* Servo calibration: pulse width at a fin angle of 90 deg and its slope. A Hitec digital servo's rated travel is
 * taken to span 900..2100 us for fin angles 0..180 deg (the linkage's calibration, per robot: measure it). */
#ifndef SERVO_CENTRE_US
#define SERVO_CENTRE_US 1500.0f
#endif
#ifndef SERVO_US_PER_RAD
#define SERVO_US_PER_RAD 381.97186f /* 1200 us / pi rad */
#endif
#define SERVO_PULSE_MIN_US 900u
#define SERVO_PULSE_MAX_US 2100u

/* Set up clock, UART, servos (both at 90 deg) and the probe pins; enables interrupts. Fills *hal. */
void hal_avr_init(pfw_hal *hal);

/* Sleep until the next interrupt (a received byte or the 1 ms tick). */
void hal_avr_idle(void);

/* Restart the hardware watchdog (armed by hal_avr_init: a hung main loop resets the MCU). */
void hal_avr_kick(void);

/* The pulse width [us] for a fin angle [rad], clamped to the servo's range; exposed for the tests. */
uint16_t hal_avr_pulse_us(float angle_rad);

/* Bytes lost because the RX ring was full (the main loop fell behind the XBee). */
uint16_t hal_avr_rx_overflows(void);

#endif /* HAL_AVR_H */
