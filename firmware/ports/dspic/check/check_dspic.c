/*
 * check_dspic.c - runs hal_dspic.c on the host against the register stubs (xc.h, libpic30.h in this folder).
 *
 * Checks the port's own arithmetic and logic, with expected values worked out by hand from hal_dspic.h's clock
 * (Fcy = 29.48 MHz): the timer periods and baud divisor, the servo pulse widths and their clamping, the receive
 * and transmit rings through the interrupt handlers, the millisecond clock, the boot id (nonzero, different at the
 * next power-up through the EEPROM counter), and one HEARTBEAT -> STATUS exchange through pfw_app over this HAL.
 * Exit status 0 when everything holds; each failure prints one line.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "hal_dspic.h"
#include "pfw.h"
#include "libpic30.h"
#include "xc.h"

/* ---------------------------------------------------------------- the stub registers */
#define DEFINE_REG(name) union stub_##name stub_##name
DEFINE_REG(T1CON); DEFINE_REG(T2CON); DEFINE_REG(T3CON); DEFINE_REG(IFS0); DEFINE_REG(IEC0); DEFINE_REG(IFS1);
DEFINE_REG(IEC1); DEFINE_REG(IPC0); DEFINE_REG(IPC6); DEFINE_REG(U2MODE); DEFINE_REG(U2STA); DEFINE_REG(OC1CON);
DEFINE_REG(OC2CON); DEFINE_REG(ADCON1); DEFINE_REG(ADCON3); DEFINE_REG(TRISD); DEFINE_REG(LATD);
uint16_t stub_TMR1, stub_PR1, stub_TMR2, stub_PR2, stub_PR3, stub_OC1R, stub_OC1RS, stub_OC2R, stub_OC2RS,
    stub_U2BRG, stub_ADPCFG, stub_ADCHS, stub_ADCON2, stub_ADCBUF0;

static uint16_t tmr3;
static uint8_t rx_fifo[512];
static size_t rx_in, rx_out;
static uint16_t tx_record[1024];
static size_t tx_count;
static uint16_t tx_sink;

uint16_t *stub_tmr3(void)
{
    tmr3 = (uint16_t)(tmr3 + 7u);
    return &tmr3;
}

stub_adcon1 *stub_adcon1_bits(void)
{
    stub_ADCON1.b.DONE = 1;
    stub_ADCBUF0 = (uint16_t)(2048u + (tmr3 & 7u)); /* a noisy mid-scale reading */
    return &stub_ADCON1.b;
}

stub_usta *stub_u2sta_bits(void)
{
    stub_U2STA.b.URXDA = rx_out != rx_in;
    stub_U2STA.b.UTXBF = 0;
    return &stub_U2STA.b;
}

uint16_t stub_u2rx_read(void)
{
    return rx_out != rx_in ? rx_fifo[rx_out++] : 0u;
}

uint16_t *stub_u2tx_slot(void)
{
    return tx_count < sizeof tx_record / sizeof tx_record[0] ? &tx_record[tx_count++] : &tx_sink;
}

void stub_idle(void) {}
void stub_clrwdt(void) {}

void _memcpy_p2d16(void *dest, _prog_addressT src, unsigned int len)
{
    memcpy(dest, (const void *)src, len);
}

void _erase_eedata(_prog_addressT dst, int len)
{
    memset((void *)dst, 0xFF, (size_t)len);
}

void _write_eedata_word(_prog_addressT dst, int dat)
{
    uint16_t word = (uint16_t)dat;
    memcpy((void *)dst, &word, sizeof word);
}

void _wait_eedata(void) {}

void _T1Interrupt(void);
void _U2RXInterrupt(void);
void _U2TXInterrupt(void);

/* ---------------------------------------------------------------- checks */
static int failures;

static void expect(int ok, const char *what, long got, long want)
{
    if (!ok) {
        printf("FAIL %s: got %ld, want %ld\n", what, got, want);
        failures++;
    }
}
#define EXPECT_EQ(what, got, want) expect((long)(got) == (long)(want), what, (long)(got), (long)(want))

static void put16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)v;
}

/* An escaped Receive Packet frame with a HEARTBEAT of session 0x01020304, seq `seq`. */
static size_t heartbeat_frame(uint8_t *out, size_t max, uint16_t seq)
{
    uint8_t data[12 + 10] = {0x90, 0, 0x13, 0xA2, 0, 0, 0, 0, 0x02, 0xFF, 0xFE, 0x01,
                             3, 0x03, 0x01, 0x02, 0x03, 0x04, 0, 0, 0, 0};
    put16(data + 18, seq);
    put16(data + 20, pfw_crc16(data + 12, 8));
    return pfw_frame_encode(data, sizeof data, out, max);
}

int main(void)
{
    pfw_hal hal;
    pfw_app app;
    pfw_config cfg;
    uint32_t first_boot;
    uint8_t buf[300];
    size_t n;

    hal_dspic_init(&hal);
    /* clock arithmetic: Fcy 29.48 MHz */
    EXPECT_EQ("PR1 (1 ms at 29.48 MHz)", stub_PR1, 29479);
    EXPECT_EQ("PR2 (20 ms at 29.48 MHz / 64)", stub_PR2, 9211);
    EXPECT_EQ("U2BRG (57600 baud: 29.48e6 / (16 * 32) = 57578)", stub_U2BRG, 31);
    EXPECT_EQ("T2 prescaler code (1:64)", stub_T2CON.b.TCKPS, 2);
    EXPECT_EQ("OC1 mode (PWM)", stub_OC1CON.b.OCM, 6);
    EXPECT_EQ("OC2 mode (PWM)", stub_OC2CON.b.OCM, 6);
    EXPECT_EQ("UART2 enabled", stub_U2MODE.b.UARTEN, 1);
    EXPECT_EQ("UART2 transmitter enabled", stub_U2STA.b.UTXEN, 1);
    EXPECT_EQ("U2RX interrupt enabled", stub_IEC1.b.U2RXIE, 1);
    EXPECT_EQ("T1 interrupt enabled", stub_IEC0.b.T1IE, 1);
    EXPECT_EQ("servo start width 1500 us = 690.9 counts", stub_OC1RS, 691);

    /* pulse widths: 460625 counts/s; 1500 us + (angle - pi/2) * 1200/pi us per rad, within 900..2100 us */
    EXPECT_EQ("90 deg -> 1500 us", hal_dspic_pulse_counts(1.5707963f), 691);
    EXPECT_EQ("10 deg -> 966.7 us", hal_dspic_pulse_counts(0.17453293f), 445);
    EXPECT_EQ("170 deg -> 2033.3 us", hal_dspic_pulse_counts(2.9670597f), 937);
    EXPECT_EQ("0 deg clamps to 900 us", hal_dspic_pulse_counts(-1.0f), 415);
    EXPECT_EQ("4 rad clamps to 2100 us", hal_dspic_pulse_counts(4.0f), 967);
    EXPECT_EQ("NaN -> 900 us", hal_dspic_pulse_counts(NAN), 415);
    hal.servo_write(hal.ctx, 1u, 0.17453293f);
    EXPECT_EQ("servo_write(left) sets OC2RS", stub_OC2RS, 445);

    /* the millisecond clock */
    for (int i = 0; i < 5; i++)
        _T1Interrupt();
    EXPECT_EQ("millis after 5 Timer1 interrupts", hal.millis(hal.ctx), 5);

    /* receive ring: order kept, 127 bytes held, the rest counted as lost */
    for (int i = 0; i < 200; i++) {
        rx_fifo[rx_in++] = (uint8_t)i;
        if (i % 4 == 3)
            _U2RXInterrupt(); /* the hardware FIFO holds 4 */
    }
    n = hal.uart_read(hal.ctx, buf, sizeof buf);
    EXPECT_EQ("bytes held by the receive ring", n, 127);
    EXPECT_EQ("first byte", buf[0], 0);
    EXPECT_EQ("last byte held", buf[126], 126);
    EXPECT_EQ("bytes lost", hal_dspic_rx_overflows(), 73);

    /* transmit ring through the interrupt */
    n = hal.uart_write(hal.ctx, (const uint8_t *)"\x7e\x01\x02", 3);
    EXPECT_EQ("bytes taken", n, 3);
    EXPECT_EQ("transmit interrupt requested", stub_IFS1.b.U2TXIF && stub_IEC1.b.U2TXIE, 1);
    _U2TXInterrupt();
    EXPECT_EQ("bytes sent", tx_count, 3);
    EXPECT_EQ("third byte sent", tx_record[2], 2);
    EXPECT_EQ("transmit interrupt off when empty", stub_IEC1.b.U2TXIE, 0);

    /* boot id: nonzero, and a new one at the next power-up (same noise: the EEPROM counter differs) */
    first_boot = hal.random32(hal.ctx);
    expect(first_boot != 0u, "boot id nonzero", (long)first_boot, 1);
    tmr3 = 0;
    hal_dspic_init(&hal);
    expect(hal.random32(hal.ctx) != first_boot, "next power-up's boot id differs", (long)hal.random32(hal.ctx),
           (long)first_boot);

    /* one exchange through the core: a HEARTBEAT in, a STATUS (an escaped 0x10 frame) out */
    pfw_config_default(&cfg);
    EXPECT_EQ("pfw_app_init", pfw_app_init(&app, &hal, &cfg), 0);
    rx_in = rx_out = 0;
    n = heartbeat_frame(rx_fifo, sizeof rx_fifo, 1);
    rx_in = n;
    for (size_t done = 0; done < n; done += 4)
        _U2RXInterrupt();
    tx_count = 0;
    for (int i = 0; i < 4; i++) {
        pfw_app_step(&app);
        _U2TXInterrupt();
    }
    EXPECT_EQ("STATUS frame starts with 0x7E", tx_count > 0 ? tx_record[0] : 0, 0x7E);
    EXPECT_EQ("STATUS frame is a Transmit Request", tx_count > 3 ? tx_record[3] : 0, 0x10);
    expect(tx_count >= 4 + 14 + 8 + 23 + 2, "STATUS frame length", (long)tx_count, 4 + 14 + 8 + 23 + 2);
    EXPECT_EQ("the robot serves the heartbeat's session", app.fw.session, 0x01020304);

    if (failures) {
        printf("check_dspic: %d failure(s)\n", failures);
        return 1;
    }
    printf("check_dspic: all checks passed (host gcc against the register stubs; XC16 not run)\n");
    return 0;
}
