/*
 * xc.h - a host stand-in for XC16's device header, for `make -C firmware dspic-check` only (NOT the device's).
 *
 * Declares the dsPIC30F6014 registers that hal_dspic.c uses, each register and its bit fields aliased through a
 * union, with the bit layout of the datasheet for the fields used. A few registers behave (a timer that counts,
 * a conversion that completes, a UART with a receive FIFO) so that hal_dspic.c's loops end and check_dspic.c can
 * drive the interrupt handlers. What this checks: that hal_dspic.c is valid C99 that compiles cleanly against
 * these names, and its arithmetic. What it cannot: that the names and bit positions are XC16's (only XC16 can).
 */
#ifndef PFW_STUB_XC_H
#define PFW_STUB_XC_H

#include <stdint.h>

#define PFW_ISR /* no interrupt attribute on the host */

#define STUB_REG(name, bits_type) \
    extern union stub_##name { uint16_t w; bits_type b; } stub_##name
#define STUB_PLAIN(name) extern uint16_t stub_##name

typedef struct { unsigned : 1, TCS : 1, TSYNC : 1, : 1, TCKPS : 2, TGATE : 1, : 6, TSIDL : 1, : 1, TON : 1; } stub_tcon;
typedef struct { unsigned INT0IF : 1, IC1IF : 1, OC1IF : 1, T1IF : 1, : 12; } stub_ifs0;
typedef struct { unsigned INT0IE : 1, IC1IE : 1, OC1IE : 1, T1IE : 1, : 12; } stub_iec0;
typedef struct { unsigned : 8, U2RXIF : 1, U2TXIF : 1, : 6; } stub_ifs1;
typedef struct { unsigned : 8, U2RXIE : 1, U2TXIE : 1, : 6; } stub_iec1;
typedef struct { unsigned INT0IP : 3, : 1, IC1IP : 3, : 1, OC1IP : 3, : 1, T1IP : 3, : 1; } stub_ipc0;
typedef struct { unsigned U2RXIP : 3, : 1, U2TXIP : 3, : 1, : 8; } stub_ipc6;
typedef struct { unsigned PDSEL : 2, STSEL : 1, : 2, ABAUD : 1, LPBACK : 1, WAKE : 1, : 5, USIDL : 1, : 1,
                 UARTEN : 1; } stub_umode;
typedef struct { unsigned URXDA : 1, OERR : 1, FERR : 1, PERR : 1, RIDLE : 1, ADDEN : 1, URXISEL : 2, TRMT : 1,
                 UTXBF : 1, UTXEN : 1, UTXBRK : 1, : 3, UTXISEL : 1; } stub_usta;
typedef struct { unsigned OCM : 3, OCTSEL : 1, OCFLT : 1, : 8, OCSIDL : 1, : 2; } stub_occon;
typedef struct { unsigned DONE : 1, SAMP : 1, ASAM : 1, : 2, SSRC : 3, FORM : 2, : 3, ADSIDL : 1, : 1,
                 ADON : 1; } stub_adcon1;
typedef struct { unsigned ADCS : 6, : 1, ADRC : 1, SAMC : 5, : 3; } stub_adcon3;
typedef struct { unsigned TRISD0 : 1, TRISD1 : 1, TRISD2 : 1, : 13; } stub_trisd;
typedef struct { unsigned LATD0 : 1, LATD1 : 1, LATD2 : 1, : 13; } stub_latd;

STUB_REG(T1CON, stub_tcon); STUB_REG(T2CON, stub_tcon); STUB_REG(T3CON, stub_tcon);
STUB_REG(IFS0, stub_ifs0); STUB_REG(IEC0, stub_iec0); STUB_REG(IFS1, stub_ifs1); STUB_REG(IEC1, stub_iec1);
STUB_REG(IPC0, stub_ipc0); STUB_REG(IPC6, stub_ipc6);
STUB_REG(U2MODE, stub_umode); STUB_REG(U2STA, stub_usta);
STUB_REG(OC1CON, stub_occon); STUB_REG(OC2CON, stub_occon);
STUB_REG(ADCON1, stub_adcon1); STUB_REG(ADCON3, stub_adcon3);
STUB_REG(TRISD, stub_trisd); STUB_REG(LATD, stub_latd);
STUB_PLAIN(TMR1); STUB_PLAIN(PR1); STUB_PLAIN(TMR2); STUB_PLAIN(PR2); STUB_PLAIN(PR3);
STUB_PLAIN(OC1R); STUB_PLAIN(OC1RS); STUB_PLAIN(OC2R); STUB_PLAIN(OC2RS);
STUB_PLAIN(U2BRG); STUB_PLAIN(ADPCFG); STUB_PLAIN(ADCHS); STUB_PLAIN(ADCON2); STUB_PLAIN(ADCBUF0);

/* Registers that behave (check_dspic.c implements them). */
uint16_t *stub_tmr3(void);               /* Timer3 advances a little at every access */
stub_adcon1 *stub_adcon1_bits(void);     /* a conversion is done as soon as it is asked */
stub_usta *stub_u2sta_bits(void);        /* URXDA: the test's receive FIFO holds a byte; UTXBF never set */
uint16_t stub_u2rx_read(void);           /* pops the test's receive FIFO */
uint16_t *stub_u2tx_slot(void);          /* each write lands in the test's transmit record */
void stub_idle(void);
void stub_clrwdt(void);

#define T1CON stub_T1CON.w
#define T1CONbits stub_T1CON.b
#define T2CON stub_T2CON.w
#define T2CONbits stub_T2CON.b
#define T3CON stub_T3CON.w
#define T3CONbits stub_T3CON.b
#define IFS0bits stub_IFS0.b
#define IEC0bits stub_IEC0.b
#define IFS1bits stub_IFS1.b
#define IEC1bits stub_IEC1.b
#define IPC0bits stub_IPC0.b
#define IPC6bits stub_IPC6.b
#define U2MODE stub_U2MODE.w
#define U2MODEbits stub_U2MODE.b
#define U2STA stub_U2STA.w
#define U2STAbits (*stub_u2sta_bits())
#define U2RXREG stub_u2rx_read()
#define U2TXREG (*stub_u2tx_slot())
#define U2BRG stub_U2BRG
#define OC1CON stub_OC1CON.w
#define OC1CONbits stub_OC1CON.b
#define OC2CON stub_OC2CON.w
#define OC2CONbits stub_OC2CON.b
#define OC1R stub_OC1R
#define OC1RS stub_OC1RS
#define OC2R stub_OC2R
#define OC2RS stub_OC2RS
#define TMR1 stub_TMR1
#define PR1 stub_PR1
#define TMR2 stub_TMR2
#define PR2 stub_PR2
#define TMR3 (*stub_tmr3())
#define PR3 stub_PR3
#define ADPCFG stub_ADPCFG
#define ADCHS stub_ADCHS
#define ADCON1 stub_ADCON1.w
#define ADCON1bits (*stub_adcon1_bits())
#define ADCON2 stub_ADCON2
#define ADCON3 stub_ADCON3.w
#define ADCON3bits stub_ADCON3.b
#define ADCBUF0 stub_ADCBUF0
#define TRISDbits stub_TRISD.b
#define LATDbits stub_LATD.b
#define Idle() stub_idle()
#define ClrWdt() stub_clrwdt()

#endif
