/*
 * Runs the trigger firmware under simavr with its UART on a pseudo-terminal, for tests.
 *
 *   sim_host trigger.elf [--vsync HZ] [--edges FILE]
 *
 * Prints "PTY /dev/pts/N" on stdout once the UART is wired (open it with pyserial).
 * --vsync HZ  drives the INT0 pin (PD2) with a rising edge every 1/HZ s of simulated time,
 *             like a projector's vsync.
 * --edges F   logs every TRIG (PB0) edge: "<cycle> <trig> <mark>", the levels after the edge.
 *             The file ends with "END <cycle> <frequency>" when the host exits.
 * SIGUSR1     resets the MCU (a power glitch: EEPROM survives, RAM and IO do not).
 * SIGTERM/INT exits cleanly (the edge log is flushed).
 *
 * The UART bridge is our own, not simavr's uart_pty part: uart_pty moves bytes in a second thread
 * without locking and symlinks a fixed /tmp/simavr-uart0 that parallel runs fight over. Here all
 * UART traffic stays on the simulation thread: a simulated-time timer polls the pty every 0.5 ms
 * (RX), and the UART output hook writes each byte to the pty at once (TX). simavr's own sleep keeps
 * simulated time in step with the wall clock. (With two CPU-bound processes on this 2-core machine,
 * pty round trips still stalled for 0.1-2 s now and then, with either bridge: that delay is outside
 * the simulator, between its pty write and the reader's wake-up.)
 */
#include <errno.h>
#include <fcntl.h>
#include <pty.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <unistd.h>

#include "avr_ioport.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_cycle_timers.h"
#include "sim_elf.h"
#include "sim_irq.h"
#include "sim_time.h"

static volatile sig_atomic_t want_reset, want_quit;
static avr_t *avr;
static int pty_master = -1, pty_slave = -1;
static avr_irq_t *uart_in;
static int uart_xon;
static uint8_t rx_pending[512];
static size_t rx_len, rx_done;
static avr_cycle_count_t last_poll; /* when poll_pty last ran: a reset (even the watchdog's) clears timers */
#define POLL_USEC 500
static FILE *edges;
static uint8_t last_portb;
static avr_cycle_count_t vsync_period;
static avr_irq_t *vsync_pin;

static void on_signal(int sig) {
    if (sig == SIGUSR1) want_reset = 1;
    else want_quit = 1;
}

/* Whole-port hook: PB0 and PB1 change in one write, so MARK is read in the same update as TRIG. */
static void on_portb(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    if (((value ^ last_portb) & 1) && edges)
        fprintf(edges, "%llu %u %u\n", (unsigned long long)avr->cycle, (unsigned)(value & 1),
                (unsigned)((value >> 1) & 1));
    last_portb = (uint8_t)value;
}

static avr_cycle_count_t vsync_edge(avr_t *a, avr_cycle_count_t when, void *param);

/* TX: every byte the MCU sends goes to the pty at once (dropped if nobody reads and it is full). */
static void on_uart_out(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)param;
    uint8_t b = (uint8_t)value;
    while (write(pty_master, &b, 1) < 0 && errno == EINTR) {
    }
}

static void feed_rx(void) {
    while (uart_xon && rx_done < rx_len) avr_raise_irq(uart_in, rx_pending[rx_done++]);
}

static void on_xon(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)value;
    (void)param;
    uart_xon = 1;
    feed_rx();
}

static void on_xoff(avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    (void)value;
    (void)param;
    uart_xon = 0;
}

/* RX: poll the pty on the simulation thread, in simulated time. */
static avr_cycle_count_t poll_pty(avr_t *a, avr_cycle_count_t when, void *param) {
    (void)param;
    last_poll = a->cycle;
    if (rx_done == rx_len) {
        ssize_t n = read(pty_master, rx_pending, sizeof(rx_pending));
        rx_len = n > 0 ? (size_t)n : 0;
        rx_done = 0;
    }
    feed_rx();
    return when + avr_usec_to_cycles(a, POLL_USEC);
}

static void open_pty(void) {
    char name[128];
    struct termios tio;
    if (openpty(&pty_master, &pty_slave, name, NULL, NULL) < 0) {
        perror("sim_host: openpty");
        exit(2);
    }
    /* raw both ways; the slave stays open here so the master never sees EIO when the host closes */
    tcgetattr(pty_slave, &tio);
    cfmakeraw(&tio);
    tcsetattr(pty_slave, TCSANOW, &tio);
    fcntl(pty_master, F_SETFL, fcntl(pty_master, F_GETFL) | O_NONBLOCK);
    printf("PTY %s\n", name);
    fflush(stdout);
}

static void connect_uart(void) {
    uint32_t f = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &f);
    f &= ~AVR_UART_FLAG_STDIO; /* no console echo: this is binary-safe, and stdout is a pipe */
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &f);
    uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), on_uart_out, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), on_xon, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), on_xoff, NULL);
}

static void start_timers(double vsync_hz) {
    last_poll = avr->cycle;
    avr_cycle_timer_register_usec(avr, POLL_USEC, poll_pty, NULL);
    if (vsync_hz > 0) avr_cycle_timer_register(avr, vsync_period, vsync_edge, NULL);
}

static avr_cycle_count_t vsync_low(avr_t *a, avr_cycle_count_t when, void *param) {
    (void)a;
    (void)param;
    avr_raise_irq(vsync_pin, 0);
    (void)when;
    return 0;
}

static avr_cycle_count_t vsync_edge(avr_t *a, avr_cycle_count_t when, void *param) {
    avr_raise_irq(vsync_pin, 1);
    avr_cycle_timer_register(a, vsync_period / 2, vsync_low, param);
    return when + vsync_period;
}

int main(int argc, char **argv) {
    const char *elf = NULL, *edges_path = NULL;
    double vsync_hz = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--vsync") && i + 1 < argc) vsync_hz = atof(argv[++i]);
        else if (!strcmp(argv[i], "--edges") && i + 1 < argc) edges_path = argv[++i];
        else elf = argv[i];
    }
    if (!elf) {
        fprintf(stderr, "usage: %s trigger.elf [--vsync HZ] [--edges FILE]\n", argv[0]);
        return 2;
    }
    elf_firmware_t fw;
    memset(&fw, 0, sizeof(fw));
    if (elf_read_firmware(elf, &fw) != 0) {
        fprintf(stderr, "sim_host: cannot read %s\n", elf);
        return 2;
    }
    strcpy(fw.mmcu, "atmega328p");
    fw.frequency = 16000000;
    avr = avr_make_mcu_by_name(fw.mmcu);
    if (!avr) {
        fprintf(stderr, "sim_host: simavr has no atmega328p\n");
        return 2;
    }
    avr_init(avr);
    avr_load_firmware(avr, &fw);
    avr->log = LOG_WARNING;

    if (edges_path && !(edges = fopen(edges_path, "w"))) {
        perror(edges_path);
        return 2;
    }
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), IOPORT_IRQ_PIN_ALL), on_portb, NULL);

    vsync_pin = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 2);
    if (vsync_hz > 0) {
        vsync_period = (avr_cycle_count_t)(avr->frequency / vsync_hz + 0.5);
        avr_raise_irq(vsync_pin, 0);
    }
    connect_uart();
    start_timers(vsync_hz);
    open_pty();

    signal(SIGUSR1, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    while (!want_quit) {
        int state = avr_run(avr);
        if (state == cpu_Done || state == cpu_Crashed) {
            fprintf(stderr, "sim_host: MCU stopped (state %d)\n", state);
            break;
        }
        if (want_reset) {
            want_reset = 0;
            avr_reset(avr);
        }
        /* after any reset (ours or the watchdog's) the cycle timers are gone: start them again */
        if (avr->cycle < last_poll || avr->cycle - last_poll > 4 * avr_usec_to_cycles(avr, POLL_USEC))
            start_timers(vsync_hz);
    }
    if (edges) {
        fprintf(edges, "END %llu %u\n", (unsigned long long)avr->cycle, (unsigned)avr->frequency);
        fclose(edges);
    }
    close(pty_master);
    close(pty_slave);
    return 0;
}
