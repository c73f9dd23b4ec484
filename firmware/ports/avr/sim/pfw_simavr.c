/*
 * pfw_simavr: runs the AVR port of the robot firmware on simavr (instruction-level, cycle-counted) and
 * connects it to the PC stack.
 *
 *   pfw_simavr [options] FIRMWARE.elf
 *
 * What it does:
 *  - Loads the ELF into an ATmega2560 at 16 MHz (simavr's model of the part: core, timers, USART, ADC).
 *  - Bridges USART0 (the XBee's line) to TCP clients on 127.0.0.1 (--tcp PORT) through a virtual pair of XBee
 *    modules (xbee_pair.h): the PC writes Transmit Requests, as to its XBee, and reads Receive Packets, so
 *    RadioLink("socket://127.0.0.1:PORT") talks to the simulated microcontroller as to the emulator. Every
 *    client hears every reply (radios on one channel). The UART side runs at the simulated baud rate.
 *  - Measures the firmware's probe pins PA0..PA2 (high while the firmware works: see firmware/ports/avr/hal_avr.c):
 *    count, longest high time in cycles and when it happened.
 *  - Measures the servo pulses on OC1A (PB5) and OC1B (PB6) and optionally logs every change of width.
 *  - With --stack-floor ADDR (the address of the symbol _end), reports the stack's high-water mark: the firmware
 *    paints the free RAM at boot, and the lowest byte the stack overwrote is found at exit.
 *  - Feeds noise to the ADC (the boot id's entropy source) from --adc-seed, so each run gets its own boot id.
 *  - --profile FILE writes a flat profile of the cycles spent while PA1 is high: "address cycles" per
 *    instruction (map the addresses to functions with avr-nm -n; sim/profile.py does).
 *  - --lockstep: the caller drives time on stdin, one command a line: "R <ms>" runs the MCU to that simulated
 *    millisecond, then prints "T <hex>" (USART0 bytes sent since), "E <hex>" (USART1 bytes: the events build's
 *    fin events) and "K"; "B <hex>" queues bytes for USART0 (Receive Packet frames, as the robot's XBee delivers
 *    them: no re-framing); "Q" ends the run.
 *  - --realtime paces simulated time to the wall clock (times --speed); without it the simulation runs free.
 *  - Stops after --run-ms simulated milliseconds, on SIGINT/SIGTERM, or (--until-disconnect) when the last
 *    client leaves; then prints a JSON report on stdout (or --report FILE).
 */
#define _POSIX_C_SOURCE 200809L

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <simavr/avr_adc.h>
#include <simavr/avr_ioport.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>

#include "xbee_pair.h"

#define MAX_CLIENTS 4
#define N_PROBES 3
#define N_SERVOS 2
#define TO_MCU_CAPACITY 65536u

typedef struct {
    uint64_t count, total, max, max_at, rise;
    int high;
} probe_t;

typedef struct {
    uint64_t rise, pulses;
    double first_us, last_us, min_us, max_us, logged_us; /* min, max: from the second pulse on (see on_servo) */
    int high;
} servo_t;

static volatile sig_atomic_t stop_requested;
static avr_t *avr;
static probe_t probes[N_PROBES];
static servo_t servos[N_SERVOS];
static FILE *servo_log;
static int clients[MAX_CLIENTS];
static int uart_xon;
static uint8_t to_mcu[TO_MCU_CAPACITY];
static size_t to_mcu_head, to_mcu_tail;
static xbee_decoder from_pc[MAX_CLIENTS], from_mcu;
static int raw_mode;
static uint64_t bytes_to_mcu, bytes_from_mcu, frames_to_mcu, frames_from_mcu, frames_consumed, queue_dropped;
static uint32_t adc_state;
static avr_irq_t *uart_input;
static uint8_t lockstep_tx[65536], lockstep_events[65536];
static size_t lockstep_tx_len, lockstep_events_len;
static int lockstep;
static uint64_t *profile; /* cycles spent at each flash byte address while PA1 is high (--profile) */

static double cycles_to_ms(uint64_t cycles) { return 1000.0 * (double)cycles / (double)avr->frequency; }

static void on_signal(int sig)
{
    (void)sig;
    stop_requested = 1;
}

static void on_probe(struct avr_irq_t *irq, uint32_t value, void *param)
{
    probe_t *p = param;
    (void)irq;
    if (value && !p->high) {
        p->rise = avr->cycle;
    } else if (!value && p->high) {
        uint64_t span = avr->cycle - p->rise;
        p->count++;
        p->total += span;
        if (span > p->max) {
            p->max = span;
            p->max_at = p->rise;
        }
    }
    p->high = value != 0;
}

static void on_servo(struct avr_irq_t *irq, uint32_t value, void *param)
{
    servo_t *s = param;
    (void)irq;
    if (value && !s->high) {
        s->rise = avr->cycle;
    } else if (!value && s->high) {
        double us = 1e6 * (double)(avr->cycle - s->rise) / (double)avr->frequency;
        /* The first pulse is the timer's start (simavr 1.6 gives a sub-microsecond one there), not a command. */
        if (s->pulses == 0)
            s->first_us = us;
        if (s->pulses == 1 || (s->pulses > 1 && us < s->min_us))
            s->min_us = us;
        if (s->pulses == 1 || (s->pulses > 1 && us > s->max_us))
            s->max_us = us;
        s->pulses++;
        s->last_us = us;
        if (servo_log && (s->pulses == 1 || us > s->logged_us + 0.75 || us < s->logged_us - 0.75)) {
            fprintf(servo_log, "%.3f %d %.1f\n", cycles_to_ms(s->rise), (int)(s - servos), us);
            s->logged_us = us;
        }
    }
    s->high = value != 0;
}

static void feed_mcu(void)
{
    while (uart_xon && to_mcu_tail != to_mcu_head) {
        uint8_t byte = to_mcu[to_mcu_tail];
        to_mcu_tail = (to_mcu_tail + 1) % TO_MCU_CAPACITY;
        bytes_to_mcu++;
        avr_raise_irq(uart_input, byte); /* may call on_xoff re-entrantly */
    }
}

static void on_xon(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq, (void)value, (void)param;
    uart_xon = 1;
    feed_mcu();
}

static void on_xoff(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq, (void)value, (void)param;
    uart_xon = 0;
}

static void queue_to_mcu(const uint8_t *data, size_t len)
{
    for (size_t i = 0; i < len; i++) {
        size_t next = (to_mcu_head + 1) % TO_MCU_CAPACITY;
        if (next == to_mcu_tail) {
            queue_dropped++;
            continue;
        }
        to_mcu[to_mcu_head] = data[i];
        to_mcu_head = next;
    }
}

static void send_to_clients(const uint8_t *data, size_t len)
{
    for (int c = 0; c < MAX_CLIENTS; c++) {
        size_t done = 0;
        if (clients[c] < 0)
            continue;
        while (done < len) { /* the PC reads promptly; a client that stalls the channel is dropped */
            ssize_t n = send(clients[c], data + done, len - done, MSG_NOSIGNAL);
            if (n <= 0) {
                close(clients[c]);
                clients[c] = -1;
                break;
            }
            done += (size_t)n;
        }
    }
}

static void on_uart1_out(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq, (void)param;
    if (lockstep_events_len < sizeof lockstep_events)
        lockstep_events[lockstep_events_len++] = (uint8_t)value;
}

static void on_uart_out(struct avr_irq_t *irq, uint32_t value, void *param)
{
    uint8_t byte = (uint8_t)value, out[XBEE_MAX_ENCODED];
    size_t len, enc;
    (void)irq, (void)param;
    bytes_from_mcu++;
    if (lockstep) {
        if (lockstep_tx_len < sizeof lockstep_tx)
            lockstep_tx[lockstep_tx_len++] = byte;
        return;
    }
    if (raw_mode) {
        send_to_clients(&byte, 1);
        return;
    }
    len = xbee_decoder_feed(&from_mcu, byte);
    if (!len)
        return;
    enc = xbee_forward(from_mcu.data, len, XBEE_ROBOT_ADDRESS, out);
    if (enc) {
        frames_from_mcu++;
        send_to_clients(out, enc);
    } else {
        frames_consumed++;
    }
}

static void on_client_bytes(int c, const uint8_t *data, size_t n)
{
    uint8_t out[XBEE_MAX_ENCODED];
    if (raw_mode) {
        queue_to_mcu(data, n);
        return;
    }
    for (size_t i = 0; i < n; i++) {
        size_t len = xbee_decoder_feed(&from_pc[c], data[i]), enc;
        if (!len)
            continue;
        enc = xbee_forward(from_pc[c].data, len, XBEE_PC_ADDRESS, out);
        if (enc) {
            frames_to_mcu++;
            queue_to_mcu(out, enc);
        } else {
            frames_consumed++;
        }
    }
}

/* The ADC answers every conversion with a noisy voltage near mid-scale: thermal noise on a floating input. */
static void on_adc_trigger(struct avr_irq_t *irq, uint32_t value, void *param)
{
    avr_adc_mux_t mux;
    (void)irq, (void)param;
    memcpy(&mux, &value, sizeof mux < sizeof value ? sizeof mux : sizeof value);
    adc_state ^= adc_state << 13;
    adc_state ^= adc_state >> 17;
    adc_state ^= adc_state << 5;
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, mux.src), 2400u + (adc_state % 200u));
}

static void no_sleep(avr_t *a, avr_cycle_count_t how_long)
{
    (void)a, (void)how_long; /* the harness paces time itself (--realtime) */
}

static int listen_on(int port, int *bound)
{
    struct sockaddr_in addr;
    socklen_t size = sizeof addr;
    int one = 1, fd = socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0)
        return -1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    memset(&addr, 0, sizeof addr);
    addr.sin_family = AF_INET;
    addr.sin_port = htons((uint16_t)port);
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (bind(fd, (struct sockaddr *)&addr, sizeof addr) < 0 || listen(fd, 4) < 0) {
        close(fd);
        return -1;
    }
    getsockname(fd, (struct sockaddr *)&addr, &size);
    *bound = ntohs(addr.sin_port);
    fcntl(fd, F_SETFL, O_NONBLOCK);
    return fd;
}

static double wall_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Accept new clients and read what they sent; wait at most timeout_ms. Returns the number of clients. */
static int serve_clients(int listener, int timeout_ms)
{
    struct pollfd fds[MAX_CLIENTS + 1];
    int n = 0, map[MAX_CLIENTS + 1], live = 0;
    if (listener >= 0) {
        fds[n].fd = listener;
        fds[n].events = POLLIN;
        map[n++] = -1;
    }
    for (int c = 0; c < MAX_CLIENTS; c++) {
        if (clients[c] >= 0) {
            fds[n].fd = clients[c];
            fds[n].events = POLLIN;
            map[n++] = c;
        }
    }
    if (n == 0 || poll(fds, (nfds_t)n, timeout_ms) <= 0)
        goto count;
    for (int i = 0; i < n; i++) {
        if (!(fds[i].revents & (POLLIN | POLLHUP | POLLERR)))
            continue;
        if (map[i] < 0) {
            int fd = accept(listener, NULL, NULL), one = 1;
            if (fd < 0)
                continue;
            setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
            for (int c = 0; c < MAX_CLIENTS; c++) {
                if (clients[c] < 0) {
                    clients[c] = fd;
                    xbee_decoder_init(&from_pc[c]);
                    fd = -1;
                    break;
                }
            }
            if (fd >= 0)
                close(fd); /* channel full */
        } else {
            uint8_t buf[4096];
            ssize_t got = recv(fds[i].fd, buf, sizeof buf, 0);
            if (got <= 0) {
                close(clients[map[i]]);
                clients[map[i]] = -1;
            } else {
                on_client_bytes(map[i], buf, (size_t)got);
            }
        }
    }
count:
    for (int c = 0; c < MAX_CLIENTS; c++)
        live += clients[c] >= 0;
    return live;
}

static void print_hex(char tag, const uint8_t *data, size_t len)
{
    putchar(tag);
    putchar(' ');
    for (size_t i = 0; i < len; i++)
        printf("%02x", data[i]);
    putchar('\n');
}

/* Lockstep: answer the last run, then read commands until the next run. Returns the cycle to run to, 0 to quit. */
static uint64_t lockstep_command(void)
{
    static char line[1 << 17];
    print_hex('T', lockstep_tx, lockstep_tx_len);
    print_hex('E', lockstep_events, lockstep_events_len);
    lockstep_tx_len = lockstep_events_len = 0;
    puts("K");
    fflush(stdout);
    while (fgets(line, sizeof line, stdin)) {
        if (line[0] == 'R') {
            uint64_t target = (uint64_t)(strtod(line + 1, NULL) * (double)avr->frequency / 1000.0);
            return target > avr->cycle ? target : avr->cycle + 1u;
        }
        if (line[0] == 'B') {
            const char *hex = line + 1;
            while (*hex == ' ')
                hex++;
            for (; hex[0] && hex[1] && hex[0] != '\n'; hex += 2) {
                unsigned byte;
                if (sscanf(hex, "%2x", &byte) != 1)
                    break;
                uint8_t b = (uint8_t)byte;
                queue_to_mcu(&b, 1);
            }
            feed_mcu();
            continue;
        }
        if (line[0] == 'Q')
            break;
    }
    return 0;
}

static void usage(const char *prog)
{
    fprintf(stderr,
            "usage: %s [--mcu NAME] [--freq HZ] [--tcp PORT] [--raw] [--realtime] [--speed X] [--run-ms MS]\n"
            "          [--until-disconnect] [--servo-log FILE] [--stack-floor ADDR] [--adc-seed N]\n"
            "          [--report FILE] [--profile FILE] FIRMWARE.elf\n",
            prog);
}

static void report(FILE *out, const char *elf, int stack_floor)
{
    fprintf(out, "{\"firmware\": \"%s\", \"mcu\": \"%s\", \"frequency\": %" PRIu32 ", \"cycles\": %" PRIu64
                 ", \"sim_ms\": %.3f,\n", elf, avr->mmcu, avr->frequency, (uint64_t)avr->cycle,
            cycles_to_ms(avr->cycle));
    fprintf(out, " \"state\": %d, \"uart\": {\"bytes_to_mcu\": %" PRIu64 ", \"bytes_from_mcu\": %" PRIu64
                 ", \"frames_to_mcu\": %" PRIu64 ", \"frames_from_mcu\": %" PRIu64 ", \"frames_consumed\": %" PRIu64
                 ", \"bad_frames_from_mcu\": %" PRIu32 ", \"queue_dropped\": %" PRIu64 "},\n",
            avr->state, bytes_to_mcu, bytes_from_mcu, frames_to_mcu, frames_from_mcu, frames_consumed,
            from_mcu.bad, queue_dropped);
    fprintf(out, " \"probes\": [");
    for (int i = 0; i < N_PROBES; i++)
        fprintf(out, "%s{\"pin\": \"PA%d\", \"count\": %" PRIu64 ", \"max_cycles\": %" PRIu64
                     ", \"max_at_ms\": %.3f, \"total_cycles\": %" PRIu64 "}", i ? ", " : "", i, probes[i].count,
                probes[i].max, cycles_to_ms(probes[i].max_at), probes[i].total);
    fprintf(out, "],\n \"servos\": [");
    for (int i = 0; i < N_SERVOS; i++)
        fprintf(out, "%s{\"pin\": \"%s\", \"pulses\": %" PRIu64 ", \"last_us\": %.2f, \"min_us\": %.2f, "
                     "\"max_us\": %.2f, \"first_us\": %.2f}", i ? ", " : "", i ? "OC1B" : "OC1A", servos[i].pulses, servos[i].last_us,
                servos[i].min_us, servos[i].max_us, servos[i].first_us);
    fprintf(out, "]");
    if (stack_floor > 0) {
        int ramend = (int)avr->ramend, lowest = ramend + 1;
        for (int a = stack_floor; a <= ramend; a++) {
            if (avr->data[a] != 0xC5) { /* the paint byte of hal_avr.c */
                lowest = a;
                break;
            }
        }
        fprintf(out, ",\n \"stack\": {\"floor\": %d, \"ramend\": %d, \"deepest\": %d, \"used_bytes\": %d, "
                     "\"never_touched_bytes\": %d}", stack_floor, ramend, lowest, ramend + 1 - lowest,
                lowest - stack_floor);
    }
    fprintf(out, "}\n");
}

int main(int argc, char **argv)
{
    const char *mcu = "atmega2560", *elf = NULL, *report_path = NULL;
    uint32_t freq = 16000000u;
    int tcp = -1, realtime = 0, until_disconnect = 0, stack_floor = 0, listener = -1, port = 0, had_client = 0;
    double speed = 1.0, run_ms = -1.0;
    const char *profile_path = NULL;
    elf_firmware_t fw;
    uint64_t chunk, next_service;
    double wall0;

    adc_state = 0x9E3779B9u;
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--raw")) raw_mode = 1;
        else if (!strcmp(a, "--lockstep")) lockstep = 1;
        else if (!strcmp(a, "--realtime")) realtime = 1;
        else if (!strcmp(a, "--until-disconnect")) until_disconnect = 1;
        else if (a[0] == '-' && a[1] == '-' && !v) { usage(argv[0]); return 2; }
        else if (!strcmp(a, "--mcu")) mcu = argv[++i];
        else if (!strcmp(a, "--freq")) freq = (uint32_t)strtoul(argv[++i], NULL, 0);
        else if (!strcmp(a, "--tcp")) tcp = atoi(argv[++i]);
        else if (!strcmp(a, "--speed")) speed = atof(argv[++i]);
        else if (!strcmp(a, "--run-ms")) run_ms = atof(argv[++i]);
        else if (!strcmp(a, "--servo-log")) servo_log = fopen(argv[++i], "w");
        else if (!strcmp(a, "--stack-floor")) stack_floor = (int)strtol(argv[++i], NULL, 0);
        else if (!strcmp(a, "--adc-seed")) adc_state = (uint32_t)strtoul(argv[++i], NULL, 0) | 1u;
        else if (!strcmp(a, "--report")) report_path = argv[++i];
        else if (!strcmp(a, "--profile")) profile_path = argv[++i];
        else if (a[0] != '-' && !elf) elf = a;
        else { usage(argv[0]); return 2; }
    }
    if (!elf || speed <= 0.0 || freq == 0) {
        usage(argv[0]);
        return 2;
    }
    memset(&fw, 0, sizeof fw);
    if (elf_read_firmware(elf, &fw) != 0) {
        fprintf(stderr, "pfw_simavr: cannot read %s\n", elf);
        return 1;
    }
    avr = avr_make_mcu_by_name(mcu);
    if (!avr) {
        fprintf(stderr, "pfw_simavr: unknown MCU %s\n", mcu);
        return 1;
    }
    avr_init(avr);
    avr->frequency = freq;
    avr_load_firmware(avr, &fw);
    avr->frequency = freq; /* the ELF's .mmcu section may not name one */
    avr->sleep = no_sleep;
    avr->log = 1;

    for (int c = 0; c < MAX_CLIENTS; c++)
        clients[c] = -1;
    xbee_decoder_init(&from_mcu);
    {
        uint32_t flags = 0;
        avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
        flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
        avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    }
    uart_input = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), on_uart_out, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('1'), UART_IRQ_OUTPUT), on_uart1_out, NULL);
    {
        uint32_t flags = 0;
        avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('1'), &flags);
        flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
        avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('1'), &flags);
    }
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), on_xon, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), on_xoff, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_OUT_TRIGGER), on_adc_trigger, NULL);
    for (int i = 0; i < N_PROBES; i++)
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('A'), i), on_probe, &probes[i]);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 5), on_servo, &servos[0]);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 6), on_servo, &servos[1]);

    if (tcp >= 0) {
        listener = listen_on(tcp, &port);
        if (listener < 0) {
            fprintf(stderr, "pfw_simavr: cannot listen on 127.0.0.1:%d: %s\n", tcp, strerror(errno));
            return 1;
        }
        printf("listening socket://127.0.0.1:%d\n", port);
        fflush(stdout);
    }
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);

    chunk = freq / 1000u; /* service the sockets and the pacing every simulated millisecond */
    next_service = chunk;
    wall0 = wall_s();
    if (lockstep) {
        uint64_t target = lockstep_command(); /* the first command: nothing has run yet */
        while (target && !stop_requested) {
            while (avr->cycle < target) {
                int state = avr_run(avr);
                if (state == cpu_Done || state == cpu_Crashed) {
                    fprintf(stderr, "pfw_simavr: the MCU %s\n", state == cpu_Done ? "stopped" : "crashed");
                    target = 0;
                    break;
                }
                feed_mcu();
            }
            if (target)
                target = lockstep_command();
        }
        stop_requested = 1; /* skip the free-running loop: report and end */
    }
    if (profile_path)
        profile = calloc((size_t)avr->flashend + 1u, sizeof *profile);
    while (!stop_requested) {
        avr_flashaddr_t pc = avr->pc;
        avr_cycle_count_t before = avr->cycle;
        int state = avr_run(avr);
        if (profile && probes[1].high && pc <= avr->flashend)
            profile[pc] += avr->cycle - before;
        if (state == cpu_Done || state == cpu_Crashed) {
            fprintf(stderr, "pfw_simavr: the MCU %s at %.3f ms\n", state == cpu_Done ? "stopped" : "crashed",
                    cycles_to_ms(avr->cycle));
            break;
        }
        if (avr->cycle < next_service)
            continue;
        next_service = avr->cycle + chunk;
        if (run_ms >= 0.0 && cycles_to_ms(avr->cycle) >= run_ms)
            break;
        if (listener >= 0) {
            int wait_ms = 0, live;
            if (realtime) {
                double ahead = cycles_to_ms(avr->cycle) / speed - 1000.0 * (wall_s() - wall0);
                wait_ms = ahead > 1.0 ? (int)ahead : 0;
            }
            live = serve_clients(listener, wait_ms);
            had_client |= live > 0;
            if (until_disconnect && had_client && live == 0)
                break;
            feed_mcu();
        } else if (realtime) {
            double ahead = cycles_to_ms(avr->cycle) / speed - 1000.0 * (wall_s() - wall0);
            if (ahead > 1.0) {
                struct timespec ts = {0, (long)(ahead * 1e6)};
                nanosleep(&ts, NULL);
            }
        }
    }
    if (report_path) {
        FILE *out = fopen(report_path, "w");
        if (!out) {
            fprintf(stderr, "pfw_simavr: cannot write %s\n", report_path);
            return 1;
        }
        report(out, elf, stack_floor);
        fclose(out);
    } else {
        report(stdout, elf, stack_floor);
    }
    if (servo_log)
        fclose(servo_log);
    if (profile) {
        FILE *out = fopen(profile_path, "w");
        for (uint32_t a = 0; out && a <= avr->flashend; a++)
            if (profile[a])
                fprintf(out, "%" PRIx32 " %" PRIu64 "\n", a, profile[a]);
        if (out)
            fclose(out);
        free(profile);
    }
    for (int c = 0; c < MAX_CLIENTS; c++)
        if (clients[c] >= 0)
            close(clients[c]);
    if (listener >= 0)
        close(listener);
    return avr->state == cpu_Crashed ? 3 : 0;
}
