/*
 * The C anchors of underfoot's benches: plain, straightforward C loops of the same work
 * as the Rust code they are compared with, written from the equations (see the README of
 * this directory). Compiled twice by build.rs: `-O3` (the anchor the acceptance ratios
 * use) and `-O3 -march=native` (reported beside it), each build's symbols prefixed by
 * UF_PREFIX so both link into one bench.
 *
 * Nothing here is tuned by hand (no intrinsics, no reordering of sums): a competent C
 * programmer's direct loops, which the compiler is free to vectorise as it can without
 * -ffast-math (it may not reorder a floating-point sum).
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#ifndef UF_PREFIX
#define UF_PREFIX uf_o3_
#endif
#define UF_CAT2(a, b) a##b
#define UF_CAT(a, b) UF_CAT2(a, b)
#define UF(name) UF_CAT(UF_PREFIX, name)

#define UF_MAX_MODES 32
#define UF_MAX_SLOTS 8

/* ---------------------------------------------------------------------------------- */
/* Engine: voices of 8 parallel biquads (the modes, summed) then 3 in series (the post  */
/* filter), f32, transposed direct form II.                                             */
/* ---------------------------------------------------------------------------------- */

#define UF_PARALLEL 8
#define UF_SERIES 3

typedef struct {
    float b0, b1, b2, a1, a2;
} uf_coef;

typedef struct {
    uf_coef mode[UF_PARALLEL];
    uf_coef post[UF_SERIES];
    float ms1[UF_PARALLEL], ms2[UF_PARALLEL];
    float ps1[UF_SERIES], ps2[UF_SERIES];
} uf_voice;

/* `coefs` holds, per voice, 11 rows of (b0, b1, b2, a1, a2): 8 modes then 3 post. */
void *UF(voices_new)(int voices, const float *coefs) {
    uf_voice *v = calloc((size_t)voices, sizeof(uf_voice));
    if (!v) return 0;
    for (int i = 0; i < voices; i++) {
        const float *c = coefs + (size_t)i * 11 * 5;
        for (int k = 0; k < UF_PARALLEL + UF_SERIES; k++) {
            uf_coef q = {c[5 * k], c[5 * k + 1], c[5 * k + 2], c[5 * k + 3], c[5 * k + 4]};
            if (k < UF_PARALLEL)
                v[i].mode[k] = q;
            else
                v[i].post[k - UF_PARALLEL] = q;
        }
    }
    return v;
}

void UF(voices_free)(void *p) { free(p); }

/* One block: `in` is voice-major (voice i's frames at in[i*frames..]), `out` is
 * interleaved (frame n of voice i at out[n*voices + i]), as the engine writes it. */
void UF(voices_process)(void *p, int voices, const float *in, float *out, int frames) {
    uf_voice *vs = p;
    for (int i = 0; i < voices; i++) {
        uf_voice *v = &vs[i];
        const float *x = in + (size_t)i * frames;
        for (int n = 0; n < frames; n++) {
            float xn = x[n];
            float acc = 0.0f;
            for (int k = 0; k < UF_PARALLEL; k++) {
                const uf_coef *c = &v->mode[k];
                float y = c->b0 * xn + v->ms1[k];
                v->ms1[k] = c->b1 * xn - c->a1 * y + v->ms2[k];
                v->ms2[k] = c->b2 * xn - c->a2 * y;
                acc += y;
            }
            for (int k = 0; k < UF_SERIES; k++) {
                const uf_coef *c = &v->post[k];
                float y = c->b0 * acc + v->ps1[k];
                v->ps1[k] = c->b1 * acc - c->a1 * y + v->ps2[k];
                v->ps2[k] = c->b2 * acc - c->a2 * y;
                acc = y;
            }
            out[(size_t)n * voices + i] = acc;
        }
    }
}

/* ---------------------------------------------------------------------------------- */
/* Resonator bank: one complex one-pole per mode, impulse invariant (f64).              */
/*   z_k <- p_k (z_k + J),  y = sum g_k Im z_k,  v = sum Im(g_k s_k z_k)                */
/* ---------------------------------------------------------------------------------- */

typedef struct {
    int modes;
    double freq[UF_MAX_MODES], decay[UF_MAX_MODES], gain[UF_MAX_MODES];
    double pr[UF_MAX_MODES], pi[UF_MAX_MODES]; /* pole */
    double g[UF_MAX_MODES];                    /* |g_k|, the displacement's gain */
    double sr[UF_MAX_MODES], si[UF_MAX_MODES]; /* g_k s_k, the velocity's */
    double zr[UF_MAX_MODES], zi[UF_MAX_MODES]; /* state */
} uf_bank;

static void bank_tune(uf_bank *b, double rate, double scale) {
    const double tau = 6.283185307179586;
    for (int k = 0; k < b->modes; k++) {
        double f = b->freq[k] * scale;
        if (f > 0.49 * rate) f = 0.49 * rate;
        double d = b->decay[k] < 0.5 ? b->decay[k] : 0.5;
        double re = -1.0 / d, im = tau * f;
        double r = exp(re / rate);
        b->pr[k] = r * cos(im / rate);
        b->pi[k] = r * sin(im / rate);
        b->g[k] = fabs(b->gain[k]);
        b->sr[k] = re * b->gain[k];
        b->si[k] = im * b->gain[k];
    }
}

static void bank_init(uf_bank *b, int modes, const double *freq, const double *decay,
                      const double *gain, double rate) {
    memset(b, 0, sizeof *b);
    b->modes = modes;
    for (int k = 0; k < modes; k++) {
        b->freq[k] = freq[k];
        b->decay[k] = decay[k];
        b->gain[k] = gain[k];
    }
    bank_tune(b, rate, 1.0);
}

void *UF(bank_new)(int modes, const double *freq, const double *decay, const double *gain,
                   double rate) {
    if (modes < 1 || modes > UF_MAX_MODES) return 0;
    uf_bank *b = malloc(sizeof *b);
    if (!b) return 0;
    bank_init(b, modes, freq, decay, gain, rate);
    return b;
}

void UF(bank_free)(void *p) { free(p); }

/* Each sample of `in` is an impulse (N s); `out` receives the velocity before it, as the
 * Rust bank's `velocity()` then `tick(J)`. */
void UF(bank_process)(void *p, const double *in, float *out, int n) {
    uf_bank *b = p;
    int K = b->modes;
    for (int i = 0; i < n; i++) {
        double j = in[i];
        double v = 0.0;
        for (int k = 0; k < K; k++) {
            v += b->sr[k] * b->zi[k] + b->si[k] * b->zr[k];
            double re = b->zr[k] + j, im = b->zi[k];
            b->zr[k] = b->pr[k] * re - b->pi[k] * im;
            b->zi[k] = b->pr[k] * im + b->pi[k] * re;
        }
        out[i] = (float)v;
    }
}

/* ---------------------------------------------------------------------------------- */
/* Impact: a hammer on the bank through a Hunt-Crossley contact, explicit in time:      */
/*   x = y_h - y_s,  F = max(0, k x^a + lambda x^a (v_h - v_s)) while x > 0, else 0,     */
/*   v_h -= F T / m,  y_h += v_h T,  the surface takes the impulse F T.                 */
/* ---------------------------------------------------------------------------------- */

typedef struct {
    double mass, k, alpha, lambda, period;
    double yh, vh;
} uf_hammer;

typedef struct {
    uf_bank bank;
    uf_hammer h;
} uf_impact;

void *UF(impact_new)(int modes, const double *freq, const double *decay, const double *gain,
                     double rate, double mass, double k, double alpha, double lambda) {
    if (modes < 1 || modes > UF_MAX_MODES) return 0;
    uf_impact *s = calloc(1, sizeof *s);
    if (!s) return 0;
    bank_init(&s->bank, modes, freq, decay, gain, rate);
    s->h.mass = mass;
    s->h.k = k;
    s->h.alpha = alpha;
    s->h.lambda = lambda;
    s->h.period = 1.0 / rate;
    return s;
}

void UF(impact_free)(void *p) { free(p); }

static double bank_displacement(const uf_bank *b) {
    double y = 0.0;
    for (int k = 0; k < b->modes; k++) y += b->g[k] * b->zi[k];
    return y;
}

/* Throws the hammer: it touches the surface where it is now, at `velocity`. */
void UF(impact_strike)(void *p, double velocity) {
    uf_impact *s = p;
    s->h.yh = bank_displacement(&s->bank);
    s->h.vh = velocity;
}

/* One sample of hammer, contact and surface; returns the surface velocity. */
static inline double impact_tick(uf_bank *b, uf_hammer *h) {
    int K = b->modes;
    double ys = 0.0, vs = 0.0;
    for (int k = 0; k < K; k++) {
        ys += b->g[k] * b->zi[k];
        vs += b->sr[k] * b->zi[k] + b->si[k] * b->zr[k];
    }
    double x = h->yh - ys;
    double f = 0.0;
    if (x > 0.0) {
        double xa = pow(x, h->alpha);
        f = h->k * xa + h->lambda * xa * (h->vh - vs);
        if (f < 0.0) f = 0.0;
    }
    h->vh -= f * h->period / h->mass;
    h->yh += h->vh * h->period;
    double j = f * h->period;
    for (int k = 0; k < K; k++) {
        double re = b->zr[k] + j, im = b->zi[k];
        b->zr[k] = b->pr[k] * re - b->pi[k] * im;
        b->zi[k] = b->pr[k] * im + b->pi[k] * re;
    }
    return vs;
}

void UF(impact_process)(void *p, float *out, int n) {
    uf_impact *s = p;
    for (int i = 0; i < n; i++) out[i] = (float)impact_tick(&s->bank, &s->h);
}

/* ---------------------------------------------------------------------------------- */
/* Crumpling: Poisson micro-impacts at a rate N (events/s), each of Exp(1) energy and a  */
/* log-uniform size, into the quietest of a pool of impacts (as the tile paper's model). */
/* ---------------------------------------------------------------------------------- */

typedef struct {
    int slots;
    double rate, period, rms_speed, log_spread, to_go;
    uint64_t rng;
    long events;
    uf_impact slot[UF_MAX_SLOTS];
} uf_crumpling;

static double uniform(uint64_t *s) {
    uint64_t z = (*s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return (double)(z >> 11) / 9007199254740992.0;
}

static double exponential(uint64_t *s) { return -log(1.0 - uniform(s)); }

void *UF(crumpling_new)(int modes, const double *freq, const double *decay,
                        const double *gain, double rate, double mass, double k,
                        double alpha, double lambda, double rms_speed, double spread,
                        int slots, uint64_t seed) {
    if (slots < 1 || slots > UF_MAX_SLOTS || modes < 1 || modes > UF_MAX_MODES) return 0;
    uf_crumpling *c = calloc(1, sizeof *c);
    if (!c) return 0;
    c->slots = slots;
    c->rate = rate;
    c->period = 1.0 / rate;
    c->rms_speed = rms_speed;
    c->log_spread = log1p(spread);
    c->rng = seed;
    for (int i = 0; i < slots; i++) {
        uf_impact *s = &c->slot[i];
        bank_init(&s->bank, modes, freq, decay, gain, rate);
        s->h.mass = mass;
        s->h.k = k;
        s->h.alpha = alpha;
        s->h.lambda = lambda;
        s->h.period = c->period;
        s->h.yh = -1.0; /* far below the surface: no contact until struck */
    }
    c->to_go = exponential(&c->rng);
    return c;
}

void UF(crumpling_free)(void *p) { free(p); }

long UF(crumpling_events)(const void *p) { return ((const uf_crumpling *)p)->events; }

static void crumpling_event(uf_crumpling *c) {
    int quietest = 0;
    double least = INFINITY;
    for (int i = 0; i < c->slots; i++) {
        const uf_bank *b = &c->slot[i].bank;
        double e = 0.0;
        for (int k = 0; k < b->modes; k++)
            e += fabs(b->si[k]) * (b->zr[k] * b->zr[k] + b->zi[k] * b->zi[k]);
        if (e < least) {
            least = e;
            quietest = i;
        }
    }
    double energy = exponential(&c->rng);
    double size = exp(c->log_spread * (2.0 * uniform(&c->rng) - 1.0));
    uf_impact *s = &c->slot[quietest];
    bank_tune(&s->bank, c->rate, 1.0 / size);
    s->h.yh = bank_displacement(&s->bank);
    s->h.vh = c->rms_speed * sqrt(energy);
    c->events++;
}

/* `rate[i]` is N at sample i (events/s); `out` receives the summed surface velocity. */
void UF(crumpling_process)(void *p, const float *rate, float *out, int n) {
    uf_crumpling *c = p;
    for (int i = 0; i < n; i++) {
        double r = rate[i] > 0.0f ? rate[i] : 0.0;
        c->to_go -= r * c->period;
        while (c->to_go <= 0.0) {
            crumpling_event(c);
            c->to_go += exponential(&c->rng);
        }
        double y = 0.0;
        for (int s = 0; s < c->slots; s++) y += impact_tick(&c->slot[s].bank, &c->slot[s].h);
        out[i] = (float)y;
    }
}
