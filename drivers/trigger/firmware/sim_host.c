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
 */
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "avr_ioport.h"
#include "sim_avr.h"
#include "sim_cycle_timers.h"
#include "sim_elf.h"
#include "sim_irq.h"
#include "uart_pty.h"

static volatile sig_atomic_t want_reset, want_quit;
static avr_t *avr;
static uart_pty_t uart;
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
        avr_cycle_timer_register(avr, vsync_period, vsync_edge, NULL);
    }

    uart_pty_init(avr, &uart);
    uart_pty_connect(&uart, '0');
    printf("PTY %s\n", uart.pty.slavename);
    fflush(stdout);

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
            if (vsync_hz > 0) avr_cycle_timer_register(avr, vsync_period, vsync_edge, NULL);
        }
    }
    if (edges) {
        fprintf(edges, "END %llu %u\n", (unsigned long long)avr->cycle, (unsigned)avr->frequency);
        fclose(edges);
    }
    /* No uart_pty_stop(): it stops its thread with SIGINT, which we catch, and would wait forever. */
    return 0;
}
