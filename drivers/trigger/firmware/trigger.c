/*
 * slscan trigger box firmware: ATmega328P (Arduino Uno), 16 MHz, UART 38400 8N1.
 * Protocol: ../PROTOCOL.md. Fires TRIG (PB0/D8) on each projector vsync (INT0, PD2/D2) or from
 * Timer1 at the set rate, raises MARK (PB1/D9) with the pulse that starts each pattern cycle,
 * counts triggers, and reports every one as a `$T,count,phase*HH` line.
 *
 * Timers: Timer1 = the rate (CTC, Bresenham between two periods so the mean rate is exact),
 * Timer0 = one-shot pulse width (4 us ticks). UART RX/TX are interrupt driven ring buffers;
 * the main loop parses lines and sleeps (idle) when there is nothing to do.
 */
#include <avr/eeprom.h>
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/pgmspace.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <util/delay.h>

#ifdef SIMAVR
/* Tells simavr the MCU and clock; link with --section-start=.mmcu=0x910000 (else strings read 0xFF). */
#include "avr/avr_mcu_section.h"
AVR_MCU(F_CPU, "atmega328p");
#endif

#define FW_VERSION "1.0"
#define BAUD 38400UL
#define MAX_BODY 60

#define TRIG _BV(PB0)
#define MARK _BV(PB1)
#define LED _BV(PB5)

enum { SRC_INT, SRC_EXT, SRC_AUTO };
static const char SRC_NAMES[3][5] PROGMEM = {"INT", "EXT", "AUTO"};

/* ---- state shared with interrupts ---- */
static volatile uint8_t running;
static volatile uint8_t active; /* SRC_INT or SRC_EXT while running */
static volatile uint32_t count;
static volatile uint8_t next_phase;
static volatile uint8_t vsync_edges;
static volatile uint32_t ev_count;
static volatile uint8_t ev_phase, ev_pending;
static volatile uint16_t per_q;           /* whole timer ticks per period */
static volatile uint32_t per_r, per_den;  /* fractional part: per_r / per_den ticks */
static volatile uint32_t per_acc;
static volatile uint8_t pw_ticks = 25;    /* 100 us */

/* ---- settings (main loop only) ---- */
static uint8_t src_setting = SRC_AUTO;
static uint8_t cycle = 2;
static uint32_t rate_mhz = 60000;
static uint8_t t1_cs;
static uint16_t boot_id;

uint8_t mcusr_saved __attribute__((section(".noinit")));

/* Runs before main: keep the reset cause and stop a watchdog left running by a watchdog reset. */
void early_init(void) __attribute__((naked, used, section(".init3")));
void early_init(void) {
    mcusr_saved = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

/* ---- UART ---- */
static volatile uint8_t rx_buf[64], rx_head, rx_tail;
static volatile uint8_t tx_buf[128], tx_head, tx_tail;
static uint8_t tx_sum;

ISR(USART_RX_vect) {
    uint8_t c = UDR0;
    uint8_t n = (rx_head + 1) & 63;
    if (n != rx_tail) { /* full: drop the byte, the framing resyncs */
        rx_buf[rx_head] = c;
        rx_head = n;
    }
}

ISR(USART_UDRE_vect) {
    if (tx_head == tx_tail) {
        UCSR0B &= ~_BV(UDRIE0);
    } else {
        UDR0 = tx_buf[tx_tail];
        tx_tail = (tx_tail + 1) & 127;
    }
}

static uint8_t tx_free(void) { return (uint8_t)(tx_tail - tx_head - 1) & 127; }

static void tx_put(uint8_t c) {
    uint8_t n = (tx_head + 1) & 127;
    while (n == tx_tail) {
    } /* wait for the UDRE interrupt to make room */
    tx_buf[tx_head] = c;
    tx_head = n;
    UCSR0B |= _BV(UDRIE0);
}

static void out_ch(char c) {
    tx_put((uint8_t)c);
    tx_sum ^= (uint8_t)c;
}
static void out_str(const char *s) {
    while (*s) out_ch(*s++);
}
static void out_str_P(PGM_P s) {
    char c;
    while ((c = pgm_read_byte(s++))) out_ch(c);
}
static void out_u32(uint32_t v) {
    char b[11];
    ultoa(v, b, 10);
    out_ch(',');
    out_str(b);
}
static void out_field_P(PGM_P s) {
    out_ch(',');
    out_str_P(s);
}
static void out_begin_P(PGM_P first) {
    tx_put('$');
    tx_sum = 0;
    out_str_P(first);
}
static void out_end(void) {
    static const char hex[] PROGMEM = "0123456789ABCDEF";
    tx_put('*');
    tx_put(pgm_read_byte(&hex[tx_sum >> 4]));
    tx_put(pgm_read_byte(&hex[tx_sum & 15]));
    tx_put('\n');
}
static void out_rate(uint32_t mhz) {
    char b[11];
    uint16_t frac = mhz % 1000;
    out_u32(mhz / 1000);
    out_ch('.');
    b[0] = '0' + frac / 100;
    b[1] = '0' + frac / 10 % 10;
    b[2] = '0' + frac % 10;
    b[3] = 0;
    out_str(b);
}

/* ---- triggering ---- */
static inline void fire(void) {
    uint8_t ph = next_phase;
    PORTB |= ph == 0 ? (TRIG | MARK) : TRIG;
    TCCR0B = 0; /* one-shot pulse end on Timer0 compare A */
    TCNT0 = 0;
    OCR0A = pw_ticks - 1;
    TIFR0 = _BV(OCF0A);
    TIMSK0 = _BV(OCIE0A);
    TCCR0B = _BV(CS01) | _BV(CS00); /* /64: 4 us */
    count++;
    next_phase = ph + 1 == cycle ? 0 : ph + 1;
    ev_count = count;
    ev_phase = ph;
    ev_pending = 1;
}

ISR(TIMER0_COMPA_vect) {
    PORTB &= ~(TRIG | MARK);
    TCCR0B = 0;
    TIMSK0 = 0;
}

ISR(TIMER1_COMPA_vect) {
    fire();
    uint32_t acc = per_acc + per_r;
    uint16_t n = per_q;
    if (acc >= per_den) {
        acc -= per_den;
        n++;
    }
    per_acc = acc;
    OCR1A = n - 1;
}

ISR(INT0_vect) {
    if (vsync_edges < 255) vsync_edges++;
    if (running && active == SRC_EXT) fire();
}

/* Period of rate_mhz in ticks of the smallest prescaler that fits 16 bits: q + r/den. */
static void compute_period(void) {
    static const uint16_t pres[4] = {1, 8, 64, 256};
    for (uint8_t i = 0; i < 4; i++) {
        uint64_t num = (uint64_t)(F_CPU / pres[i]) * 1000u;
        uint64_t q = num / rate_mhz;
        if (q < 65536u || i == 3) {
            cli();
            per_q = (uint16_t)q;
            per_r = (uint32_t)(num % rate_mhz);
            per_den = rate_mhz;
            per_acc = 0;
            sei();
            t1_cs = i + 1; /* CS1x: 1=/1 2=/8 3=/64 4=/256 */
            return;
        }
    }
}

static void timer1_start(void) {
    TCCR1B = 0;
    TCCR1A = 0;
    TCNT1 = 0;
    OCR1A = per_q - 1;
    TIFR1 = _BV(OCF1A);
    TIMSK1 = _BV(OCIE1A);
    TCCR1B = _BV(WGM12) | t1_cs;
}

static void timer1_stop(void) {
    TCCR1B = 0;
    TIMSK1 = 0;
}

static void start(void) {
    uint8_t src = src_setting;
    timer1_stop();
    running = 0;
    if (src == SRC_AUTO) { /* a wired vsync shows at least two edges in 50 ms (>= 20 Hz) */
        vsync_edges = 0;
        _delay_ms(50);
        src = vsync_edges >= 2 ? SRC_EXT : SRC_INT;
    }
    cli();
    count = 0;
    next_phase = 0;
    ev_pending = 0;
    active = src;
    running = 1;
    sei();
    PORTB |= LED;
    if (src == SRC_INT) {
        compute_period();
        timer1_start();
    }
}

static void stop(void) {
    timer1_stop();
    running = 0;
    PORTB &= ~LED;
}

/* ---- commands ---- */
static void reply_err(const char *cmd, PGM_P code) {
    out_begin_P(PSTR("ERR"));
    out_ch(',');
    out_str(cmd);
    out_field_P(code);
    out_end();
}
static void reply_ok(const char *cmd) { /* caller appends fields and calls out_end() */
    out_begin_P(PSTR("OK"));
    out_ch(',');
    out_str(cmd);
}

/* Unsigned decimal, 1-6 digits, nothing else. */
static uint8_t parse_uint(const char *s, uint32_t *v) {
    uint8_t n = 0;
    uint32_t x = 0;
    for (; *s; s++, n++) {
        if (*s < '0' || *s > '9' || n >= 6) return 0;
        x = x * 10 + (uint8_t)(*s - '0');
    }
    *v = x;
    return n > 0;
}

/* '59.94' -> 59940 mHz: 1-6 digits, optionally '.' and 1-3 digits. */
static uint8_t parse_rate(const char *s, uint32_t *mhz) {
    uint32_t whole = 0, frac = 0;
    uint8_t nw = 0, nf = 0;
    for (; *s >= '0' && *s <= '9'; s++, nw++) {
        if (nw >= 6) return 0;
        whole = whole * 10 + (uint8_t)(*s - '0');
    }
    if (nw == 0) return 0;
    if (*s == '.') {
        for (s++; *s >= '0' && *s <= '9'; s++, nf++) {
            if (nf >= 3) return 0;
            frac = frac * 10 + (uint8_t)(*s - '0');
        }
        if (nf == 0) return 0;
    }
    if (*s) return 0;
    while (nf++ < 3) frac *= 10;
    *mhz = whole * 1000 + frac;
    return 1;
}

static void send_stat(void) {
    reply_ok("STAT");
    out_u32(running);
    out_field_P(SRC_NAMES[src_setting]);
    if (running) out_field_P(SRC_NAMES[active]);
    else out_field_P(PSTR("-"));
    out_rate(rate_mhz);
    out_u32(cycle);
    out_u32(pw_ticks * 4u);
    cli();
    uint32_t c = count;
    sei();
    out_u32(c);
    out_u32(boot_id);
    out_end();
}

static void handle(char *body) {
    char *argv[3];
    uint8_t argc = 0;
    argv[argc++] = body;
    for (char *p = body; *p; p++) {
        if (*p == ',') {
            *p = 0;
            if (argc == 3) { /* more fields than any command takes */
                argc++;
                break;
            }
            argv[argc++] = p + 1;
        }
    }
    char *name = argv[0];
    for (char *p = name; *p; p++)
        if (*p >= 'a' && *p <= 'z') *p -= 32;
    uint8_t nargs = argc - 1;
    uint8_t want1 = !strcmp_P(name, PSTR("RATE")) || !strcmp_P(name, PSTR("CYC")) || !strcmp_P(name, PSTR("SRC")) ||
                    !strcmp_P(name, PSTR("PW"));
    uint8_t want0 = !strcmp_P(name, PSTR("VER")) || !strcmp_P(name, PSTR("START")) || !strcmp_P(name, PSTR("STOP")) ||
                    !strcmp_P(name, PSTR("CNT")) || !strcmp_P(name, PSTR("STAT")) || !strcmp_P(name, PSTR("RESET"));
    if (!want0 && !want1) {
        if (strlen(name) > 12) name[12] = 0;
        reply_err(name, PSTR("UNKNOWN"));
        return;
    }
    if (nargs != (want1 ? 1 : 0)) {
        reply_err(name, PSTR("ARG"));
        return;
    }
    char *arg = argv[1];
    uint32_t v;
    if (!strcmp_P(name, PSTR("VER"))) {
        reply_ok(name);
        out_field_P(PSTR("SLTRIG"));
        out_field_P(PSTR(FW_VERSION));
        out_u32(boot_id);
        out_end();
    } else if (!strcmp_P(name, PSTR("RATE"))) {
        if (!parse_rate(arg, &v)) return reply_err(name, PSTR("ARG"));
        if (v < 1000 || v > 250000) return reply_err(name, PSTR("RANGE"));
        rate_mhz = v;
        if (running && active == SRC_INT) { /* the next trigger comes one new period from now */
            compute_period();
            timer1_start();
        }
        reply_ok(name);
        out_rate(rate_mhz);
        out_end();
    } else if (!strcmp_P(name, PSTR("CYC"))) {
        if (!parse_uint(arg, &v)) return reply_err(name, PSTR("ARG"));
        if (v < 1 || v > 16) return reply_err(name, PSTR("RANGE"));
        if (running) return reply_err(name, PSTR("BUSY"));
        cycle = (uint8_t)v;
        reply_ok(name);
        out_u32(cycle);
        out_end();
    } else if (!strcmp_P(name, PSTR("PW"))) {
        if (!parse_uint(arg, &v)) return reply_err(name, PSTR("ARG"));
        if (v < 8 || v > 1000) return reply_err(name, PSTR("RANGE"));
        if (running) return reply_err(name, PSTR("BUSY"));
        pw_ticks = (uint8_t)(v / 4);
        reply_ok(name);
        out_u32(pw_ticks * 4u);
        out_end();
    } else if (!strcmp_P(name, PSTR("SRC"))) {
        for (char *p = arg; *p; p++)
            if (*p >= 'a' && *p <= 'z') *p -= 32;
        uint8_t s = 255;
        for (uint8_t i = 0; i < 3; i++)
            if (!strcmp_P(arg, SRC_NAMES[i])) s = i;
        if (s == 255) return reply_err(name, PSTR("ARG"));
        if (running) return reply_err(name, PSTR("BUSY"));
        src_setting = s;
        reply_ok(name);
        out_field_P(SRC_NAMES[s]);
        out_end();
    } else if (!strcmp_P(name, PSTR("START"))) {
        start();
        reply_ok(name);
        out_field_P(SRC_NAMES[active]);
        out_end();
    } else if (!strcmp_P(name, PSTR("STOP"))) {
        stop();
        reply_ok(name);
        out_u32(count);
        out_end();
    } else if (!strcmp_P(name, PSTR("CNT"))) {
        cli();
        v = count;
        sei();
        reply_ok(name);
        out_u32(v);
        out_end();
    } else if (!strcmp_P(name, PSTR("STAT"))) {
        send_stat();
    } else { /* RESET */
        stop();
        reply_ok(name);
        out_end();
        while (tx_head != tx_tail) {
        }
        _delay_ms(3); /* the last byte leaves the shift register */
        wdt_enable(WDTO_15MS);
        for (;;) {
        }
    }
}

static uint8_t hexval(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return 255;
}

/* A complete line between '$' and '\n' (without either): check it, then run it. */
static void line_done(char *line, uint8_t len) {
    char *star = NULL;
    for (uint8_t i = 0; i < len; i++)
        if (line[i] == '*') star = &line[i];
    if (star) {
        uint8_t blen = star - line, sum = 0, ok = (len - blen == 3);
        for (uint8_t i = 0; i < blen; i++) {
            if (line[i] == '*') ok = 0;
            sum ^= (uint8_t)line[i];
        }
        if (ok) {
            uint8_t h = hexval(star[1]), l = hexval(star[2]);
            ok = h != 255 && l != 255 && ((h << 4) | l) == sum;
        }
        if (!ok) return reply_err("?", PSTR("CHECKSUM"));
        *star = 0;
        len = blen;
    } else {
        line[len] = 0;
    }
    if (len > MAX_BODY) return reply_err("?", PSTR("LONG"));
    handle(line);
}

static char line[MAX_BODY + 4];
static uint8_t line_len;
static uint8_t line_state; /* 0: discarding until '$', 1: in a line, 2: in a line that is too long */

static void rx_byte(uint8_t c) {
    if (c == '$') {
        line_state = 1;
        line_len = 0;
    } else if (line_state == 0 || c == '\r') {
    } else if (c == '\n') {
        if (line_state == 2) reply_err("?", PSTR("LONG"));
        else line_done(line, line_len);
        line_state = 0;
    } else if (c < 0x20 || c > 0x7e) {
        line_state = 0; /* garbage: wait for the next '$' */
    } else if (line_state == 1) {
        if (line_len >= MAX_BODY + 3) line_state = 2;
        else line[line_len++] = (char)c;
    }
}

static void send_event(uint32_t c, uint8_t ph) {
    out_begin_P(PSTR("T"));
    out_u32(c);
    out_u32(ph);
    out_end();
}

int main(void) {
    uint8_t cause = mcusr_saved;
    DDRB = TRIG | MARK | LED;
    PORTB = 0;
    DDRD &= ~_BV(PD2);
    PORTD |= _BV(PD2); /* pull-up: an unwired vsync input stays high, no edges */
    EICRA = _BV(ISC01) | _BV(ISC00); /* INT0 on the rising edge */
    EIMSK = _BV(INT0);
    UBRR0 = F_CPU / 16 / BAUD - 1;
    UCSR0A = 0;
    UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
    UCSR0B = _BV(RXCIE0) | _BV(RXEN0) | _BV(TXEN0);
    TCCR0A = 0;
    boot_id = eeprom_read_word((uint16_t *)0) + 1; /* erased EEPROM (0xFFFF) starts at 0 */
    eeprom_update_word((uint16_t *)0, boot_id);
    set_sleep_mode(SLEEP_MODE_IDLE);
    sei();

    out_begin_P(PSTR("BOOT"));
    out_field_P(PSTR("SLTRIG"));
    out_field_P(PSTR(FW_VERSION));
    out_u32(boot_id);
    if (cause & _BV(PORF)) out_field_P(PSTR("PWR"));
    else if (cause & _BV(BORF)) out_field_P(PSTR("BOD"));
    else if (cause & _BV(EXTRF)) out_field_P(PSTR("EXT"));
    else if (cause & _BV(WDRF)) out_field_P(PSTR("WDT"));
    else out_field_P(PSTR("?"));
    out_end();

    for (;;) {
        while (rx_tail != rx_head) {
            uint8_t c = rx_buf[rx_tail];
            rx_tail = (rx_tail + 1) & 63;
            rx_byte(c);
        }
        if (ev_pending && tx_free() >= 20) { /* else keep it pending: a newer count replaces it */
            cli();
            uint32_t c = ev_count;
            uint8_t ph = ev_phase;
            ev_pending = 0;
            sei();
            send_event(c, ph);
        }
        cli();
        if (rx_tail == rx_head && !(ev_pending && tx_free() >= 20)) {
            sleep_enable();
            sei();
            sleep_cpu();
            sleep_disable();
        }
        sei();
    }
}
