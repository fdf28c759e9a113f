/* Collision features in the compiled loops: the narrow phase of mbcomp/core/collide.py in C.

   A model with mb.Collision components has, after its own contacts, one contact row per
   candidate feature of every shape pair (compiled/collision_kernel.py).  For a compiled
   stretch between contact events Python (compiled/collision_c.py) configures, per thread:

   - the shapes ("entries": kind, body row of the kinematics or -1 for the ground, geometry
     in the body frame) and every feature (its two entries and its slot in the pair);
   - the candidates: the features of the pairs whose bounding spheres came within a margin
     at the stretch's start (the broad phase runs in Python, once per stretch), with the
     slot of each feature among them (-1: not a candidate);
   - what ends the stretch: a moving shape's bounding-sphere centre farther than `drift`
     (m) from where it started (the broad phase is then out of date), or the sum of the two
     fastest shapes' speeds above `ceiling` (m/s; the stretch's step limit assumed less).

   mb_collide_eval computes, from the body kinematics (the generated `kinematics`), every
   candidate's gap, Jacobian row n.(J_b(pb) - J_a(pa)) and acceleration bias: the numbers of
   CollisionKernel.contacts.  The formulations' C reads them for the held rows
   (mb_collide_row), the contact watch for the gaps (mb_collide_gap_of) and the end of the
   stretch (mb_collide_leaves); mb_collide_gap gives one feature's exact gap on its own (for
   locating an event).  Shape kinds are the indices of collide.ORDER; owners collide.OWNER_*. */
#define MBC_PLANE 0
#define MBC_BOX 1
#define MBC_CAPSULE 2
#define MBC_SPHERE 3
#define MBC_OWNER_A 0
#define MBC_OWNER_B 1
#define MBC_OWNER_LINE 2
#define MBC_OWNER_EDGE 3
/* doubles of an entry's geometry: origin (3), rotation (9, row-major, box), half edges or
   capsule axis or plane normal (3), radius, capsule length */
#define MBC_GEO 17
/* doubles of a body's kinematics row: rotation (9), origin (3), velocity (w, v0), bias (6) */
#define MBC_BODY_ROW 24
/* doubles per candidate in the output: gap, bias, then the Jacobian row (NV) */
#define MBC_OUT_HEAD 2
#define MBC_EDGE_PARALLEL 1e-6

typedef struct {
    int kind, body;
    double c[3], R[9], h[3], n[3], e0[3], e1[3], r;
} mbc_shape;

typedef struct {
    double gap, n[3], pa[3], pb[3], dist;
    int owner, sa, sb;   /* sa, sb: pa (pb) slides along a (b) */
    double ra, rb;       /* rounding radii at pa, pb: the surfaces touch at pa + ra n, pb - rb n */
    double a[3], b[3];
} mbc_feature;

static __thread int mbc_nf = 0, mbc_nc = 0, mbc_nw = 0;
static __thread const long *mbc_feat, *mbc_ekind, *mbc_cand, *mbc_slot, *mbc_went;
static __thread const double *mbc_egeo, *mbc_mask, *mbc_wcentre, *mbc_wradius;
static __thread double *mbc_out, *mbc_kin, mbc_drift, mbc_ceiling;

/* Configure this thread's collision features (nf < 0: off).  feat: nf x 3 (entry a, entry
   b, slot); ekind: entries x 2 (kind, body row or -1); egeo: entries x MBC_GEO; mask:
   bodies x NQ (1 where the speed moves the body); cand: nc feature indices, slot: nf
   (candidate slot or -1); out: nc x (MBC_OUT_HEAD + NQ); kin: KINEMATICS_SIZE doubles;
   went: nw watched entries, wcentre (nw x 3) their bounding-sphere centres at the start,
   wradius (nw) their bounding radii; drift (m) and ceiling (m/s) as above. */
int mb_collide_configure(int nf, const long *feat, const long *ekind, const double *egeo, const double *mask,
                         int nc, const long *cand, const long *slot, double *out, double *kin, int nw,
                         const long *went, const double *wcentre, const double *wradius, double drift,
                         double ceiling) {
    mbc_nf = nf < 0 ? 0 : nf;
    mbc_feat = feat; mbc_ekind = ekind; mbc_egeo = egeo; mbc_mask = mask;
    mbc_nc = nc < 0 ? 0 : nc; mbc_cand = cand; mbc_slot = slot; mbc_out = out; mbc_kin = kin;
    mbc_nw = nw < 0 ? 0 : nw; mbc_went = went; mbc_wcentre = wcentre; mbc_wradius = wradius;
    mbc_drift = drift; mbc_ceiling = ceiling;
    return 0;
}

/* Number of collision features configured (0: none, or switched off). */
int mb_collide_count(void) {
    return mbc_nf;
}

static double mbc_dot(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void mbc_cross(const double *a, const double *b, double *out) {
    const double x = a[1] * b[2] - a[2] * b[1], y = a[2] * b[0] - a[0] * b[2], z = a[0] * b[1] - a[1] * b[0];
    out[0] = x; out[1] = y; out[2] = z;
}

static double mbc_norm(const double *a) { return sqrt(mbc_dot(a, a)); }

static double mbc_clip(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

/* column k of a row-major 3x3 matrix */
static void mbc_col(const double *R, int k, double *out) { out[0] = R[k]; out[1] = R[3 + k]; out[2] = R[6 + k]; }

static const double *mbc_body(long b) {
    return mbc_kin + KINEMATICS_BODIES_OFF + b * MBC_BODY_ROW;
}

/* Entry e placed in the world from the kinematics in mbc_kin (CollisionKernel.placed). */
static void mbc_place(long e, mbc_shape *s) {
    static const double eye[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, zero[3] = {0, 0, 0};
    const double *g = mbc_egeo + e * MBC_GEO;
    const long body = mbc_ekind[2 * e + 1];
    const double *Rb = body < 0 ? eye : mbc_body(body), *ob = body < 0 ? zero : mbc_body(body) + 9;
    s->kind = (int)mbc_ekind[2 * e];
    s->body = (int)body;
    for (int i = 0; i < 3; ++i) {
        s->c[i] = ob[i] + Rb[3 * i] * g[0] + Rb[3 * i + 1] * g[1] + Rb[3 * i + 2] * g[2];
        s->n[i] = Rb[3 * i] * g[12] + Rb[3 * i + 1] * g[13] + Rb[3 * i + 2] * g[14];  /* normal or axis */
        for (int j = 0; j < 3; ++j)
            s->R[3 * i + j] = Rb[3 * i] * g[3 + j] + Rb[3 * i + 1] * g[6 + j] + Rb[3 * i + 2] * g[9 + j];
        s->h[i] = g[12 + i];
    }
    s->r = g[15];
    for (int i = 0; i < 3; ++i) {
        s->e0[i] = s->c[i] - 0.5 * g[16] * s->n[i];
        s->e1[i] = s->c[i] + 0.5 * g[16] * s->n[i];
    }
}

static void mbc_set(mbc_feature *f, double gap, const double *n, const double *pa, const double *pb, int owner) {
    f->gap = gap; f->owner = owner; f->dist = 0.0; f->sa = f->sb = 0; f->ra = f->rb = 0.0;
    for (int i = 0; i < 3; ++i) { f->n[i] = n[i]; f->pa[i] = pa[i]; f->pb[i] = pb[i]; f->a[i] = f->b[i] = 0.0; }
}

/* collide._line: rounded features at pa, pb with radii ra, rb */
static void mbc_line(mbc_feature *f, const double *pa, const double *pb, double ra, double rb, const double *fallback) {
    double d[3], n[3];
    for (int i = 0; i < 3; ++i) d[i] = pb[i] - pa[i];
    const double dist = mbc_norm(d);
    for (int i = 0; i < 3; ++i) n[i] = dist > 1e-12 ? d[i] / dist : fallback[i];
    mbc_set(f, dist - ra - rb, n, pa, pb, MBC_OWNER_LINE);
    f->dist = dist > 1e-12 ? dist : 1e-12;
    f->ra = ra; f->rb = rb;
}

/* collide._point_plane */
static void mbc_point_plane(mbc_feature *f, const double *p, double radius, const mbc_shape *plane) {
    double d[3], foot[3];
    for (int i = 0; i < 3; ++i) d[i] = p[i] - plane->c[i];
    const double height = mbc_dot(plane->n, d);
    for (int i = 0; i < 3; ++i) foot[i] = p[i] - height * plane->n[i];
    mbc_set(f, height - radius, plane->n, foot, p, MBC_OWNER_A);
    f->rb = radius;
}

/* collide._point_box: a sphere (a corner: radius 0) against box A */
static void mbc_point_box(mbc_feature *f, const double *p, double radius, const mbc_shape *box) {
    double local[3], clamped[3], pa[3], n[3];
    int outside[3], count = 0;
    const double *R = box->R, *h = box->h;
    for (int k = 0; k < 3; ++k) {
        local[k] = R[k] * (p[0] - box->c[0]) + R[3 + k] * (p[1] - box->c[1]) + R[6 + k] * (p[2] - box->c[2]);
        clamped[k] = mbc_clip(local[k], -h[k], h[k]);
        outside[k] = fabs(local[k]) > h[k];
        count += outside[k];
    }
    if (count) {
        for (int i = 0; i < 3; ++i) pa[i] = box->c[i] + R[3 * i] * clamped[0] + R[3 * i + 1] * clamped[1] + R[3 * i + 2] * clamped[2];
        if (count == 1) {
            const int k = outside[0] ? 0 : (outside[1] ? 1 : 2);
            const double sign = local[k] > 0.0 ? 1.0 : (local[k] < 0.0 ? -1.0 : 0.0);
            mbc_col(R, k, n);
            for (int i = 0; i < 3; ++i) n[i] *= sign;
            mbc_set(f, fabs(local[k]) - h[k] - radius, n, pa, p, MBC_OWNER_A);
            f->rb = radius;
            return;
        }
        double fb[3], sg[3];
        for (int k = 0; k < 3; ++k) sg[k] = (local[k] > 0.0 ? 1.0 : (local[k] < 0.0 ? -1.0 : 0.0)) / sqrt(3.0);
        for (int i = 0; i < 3; ++i) fb[i] = R[3 * i] * sg[0] + R[3 * i + 1] * sg[1] + R[3 * i + 2] * sg[2];
        mbc_line(f, pa, p, 0.0, radius, fb);
        if (count == 2) {  /* an edge: the nearest point slides along it */
            f->sa = 1;
            mbc_col(R, outside[0] ? (outside[1] ? 2 : 1) : 0, f->a);
        }
        return;
    }
    int k = 0;
    double depth[3];
    for (int j = 0; j < 3; ++j) depth[j] = h[j] - fabs(local[j]);
    for (int j = 1; j < 3; ++j) if (depth[j] < depth[k]) k = j;
    const double sign = local[k] >= 0.0 ? 1.0 : -1.0;
    mbc_col(R, k, n);
    for (int i = 0; i < 3; ++i) n[i] *= sign;
    local[k] = sign * h[k];
    for (int i = 0; i < 3; ++i) pa[i] = box->c[i] + R[3 * i] * local[0] + R[3 * i + 1] * local[1] + R[3 * i + 2] * local[2];
    mbc_set(f, -depth[k] - radius, n, pa, p, MBC_OWNER_A);
    f->rb = radius;
}

/* corner k of a box (collide._CORNERS order: x slowest) */
static void mbc_corner(const mbc_shape *box, int k, double *out) {
    const double s[3] = {(k & 4) ? 1.0 : -1.0, (k & 2) ? 1.0 : -1.0, (k & 1) ? 1.0 : -1.0};
    for (int i = 0; i < 3; ++i) {
        out[i] = box->c[i];
        for (int j = 0; j < 3; ++j) out[i] += box->R[3 * i + j] * s[j] * box->h[j];
    }
}

/* collide.segment_parameter */
static double mbc_segment_parameter(const double *p0, const double *p1, const double *x) {
    double d[3], r[3];
    for (int i = 0; i < 3; ++i) { d[i] = p1[i] - p0[i]; r[i] = x[i] - p0[i]; }
    const double dd = mbc_dot(d, d);
    return mbc_clip(mbc_dot(r, d) / (dd > 1e-300 ? dd : 1e-300), 0.0, 1.0);
}

static void mbc_slide_axis(const double *p0, const double *p1, double s, int *flag, double *axis) {
    *flag = 0.0 < s && s < 1.0;
    if (!*flag) return;
    for (int i = 0; i < 3; ++i) axis[i] = p1[i] - p0[i];
    const double len = mbc_norm(axis);
    for (int i = 0; i < 3; ++i) axis[i] /= len;
}

/* collide.closest_parameters: nearest points of two segments (*s, *t NaN when parallel) */
static void mbc_closest(const double *p0, const double *p1, const double *q0, const double *q1, double *pa, double *pb,
                        double *s_out, double *t_out) {
    double d1[3], d2[3], r[3];
    for (int i = 0; i < 3; ++i) { d1[i] = p1[i] - p0[i]; d2[i] = q1[i] - q0[i]; r[i] = p0[i] - q0[i]; }
    const double a = mbc_dot(d1, d1), e = mbc_dot(d2, d2), f = mbc_dot(d2, r), c = mbc_dot(d1, r), b = mbc_dot(d1, d2);
    const double denom = a * e - b * b;
    if (denom <= 1e-12 * a * e) {
        double u0[3], u1[3];
        for (int i = 0; i < 3; ++i) { u0[i] = q0[i] - p0[i]; u1[i] = q1[i] - p0[i]; }
        const double s0 = mbc_clip(mbc_dot(u0, d1) / a, 0.0, 1.0), s1 = mbc_clip(mbc_dot(u1, d1) / a, 0.0, 1.0);
        const double s = 0.5 * ((s0 < s1 ? s0 : s1) + (s0 < s1 ? s1 : s0));
        for (int i = 0; i < 3; ++i) pa[i] = p0[i] + s * d1[i];
        const double t = mbc_segment_parameter(q0, q1, pa);
        for (int i = 0; i < 3; ++i) pb[i] = q0[i] + t * d2[i];
        *s_out = *t_out = NAN;
        return;
    }
    double s = mbc_clip((b * f - c * e) / denom, 0.0, 1.0);
    double t = (b * s + f) / e;
    if (t < 0.0) { t = 0.0; s = mbc_clip(-c / a, 0.0, 1.0); }
    else if (t > 1.0) { t = 1.0; s = mbc_clip((b - c) / a, 0.0, 1.0); }
    for (int i = 0; i < 3; ++i) { pa[i] = p0[i] + s * d1[i]; pb[i] = q0[i] + t * d2[i]; }
    *s_out = s; *t_out = t;
}

/* collide.edge_edge: box A's edge along axis i against box B's along axis j */
static void mbc_edge_edge(mbc_feature *f, const mbc_shape *A, const mbc_shape *B, int i, int j) {
    double da[3], db[3], u[3], L[3], pa0[3], pb0[3], r[3], pa[3], pb[3], dc[3], col[3];
    mbc_col(A->R, i, da);
    mbc_col(B->R, j, db);
    mbc_cross(da, db, u);
    const double size = mbc_norm(u);
    if (size < MBC_EDGE_PARALLEL) {
        static const double up[3] = {0.0, 0.0, 1.0};
        mbc_set(f, mbc_norm(A->h) + mbc_norm(B->h), up, A->c, B->c, MBC_OWNER_EDGE);
        return;
    }
    for (int k = 0; k < 3; ++k) { L[k] = u[k] / size; dc[k] = B->c[k] - A->c[k]; pa0[k] = A->c[k]; pb0[k] = B->c[k]; }
    if (mbc_dot(L, dc) < 0.0) for (int k = 0; k < 3; ++k) L[k] = -L[k];
    for (int k = 0; k < 3; ++k) {
        if (k != i) {
            mbc_col(A->R, k, col);
            const double sg = mbc_dot(L, col) >= 0.0 ? 1.0 : -1.0;
            for (int m = 0; m < 3; ++m) pa0[m] += sg * A->h[k] * col[m];
        }
        if (k != j) {
            mbc_col(B->R, k, col);
            const double sg = mbc_dot(L, col) >= 0.0 ? 1.0 : -1.0;
            for (int m = 0; m < 3; ++m) pb0[m] -= sg * B->h[k] * col[m];
        }
    }
    for (int k = 0; k < 3; ++k) r[k] = pa0[k] - pb0[k];
    const double c = mbc_dot(da, db), d1 = mbc_dot(da, r), e1 = mbc_dot(db, r);
    double s = (c * e1 - d1) / (1.0 - c * c);
    double t = e1 + c * s;
    const double oa = fabs(s) - A->h[i], ob = fabs(t) - B->h[j];
    const double over = (oa > 0.0 ? oa : 0.0) + (ob > 0.0 ? ob : 0.0);
    s = mbc_clip(s, -A->h[i], A->h[i]);
    t = mbc_clip(t, -B->h[j], B->h[j]);
    for (int k = 0; k < 3; ++k) { pa[k] = pa0[k] + s * da[k]; pb[k] = pb0[k] + t * db[k]; dc[k] = pb[k] - pa[k]; }
    const double separation = mbc_dot(L, dc);
    if (over > 0.0) {
        mbc_set(f, (separation > 0.0 ? separation : 0.0) + over, L, pa, pb, MBC_OWNER_EDGE);
        return;
    }
    mbc_set(f, separation, L, pa, pb, MBC_OWNER_EDGE);
    f->sa = f->sb = 1;
    for (int k = 0; k < 3; ++k) { f->a[k] = da[k]; f->b[k] = db[k]; }
}

/* collide._swap */
static void mbc_swap(mbc_feature *f) {
    double t;
    for (int i = 0; i < 3; ++i) {
        f->n[i] = -f->n[i];
        t = f->pa[i]; f->pa[i] = f->pb[i]; f->pb[i] = t;
        t = f->a[i]; f->a[i] = f->b[i]; f->b[i] = t;
    }
    const int s = f->sa; f->sa = f->sb; f->sb = s;
    t = f->ra; f->ra = f->rb; f->rb = t;
    if (f->owner == MBC_OWNER_A) f->owner = MBC_OWNER_B;
    else if (f->owner == MBC_OWNER_B) f->owner = MBC_OWNER_A;
}

/* Feature `slot` of placed shapes a, b (collide.features), or 1 when the pair has none. */
static int mbc_features(const mbc_shape *a, const mbc_shape *b, int slot, mbc_feature *f) {
    static const double up[3] = {0.0, 0.0, 1.0};
    if (a->kind > b->kind) {
        const int status = mbc_features(b, a, slot, f);
        if (!status) mbc_swap(f);
        return status;
    }
    double p[3], pa[3], pb[3], s, t;
    switch (a->kind * 4 + b->kind) {
    case MBC_PLANE * 4 + MBC_SPHERE:
        mbc_point_plane(f, b->c, b->r, a);
        return 0;
    case MBC_PLANE * 4 + MBC_CAPSULE:
        mbc_point_plane(f, slot ? b->e1 : b->e0, b->r, a);
        return 0;
    case MBC_PLANE * 4 + MBC_BOX:
        mbc_corner(b, slot, p);
        mbc_point_plane(f, p, 0.0, a);
        return 0;
    case MBC_BOX * 4 + MBC_SPHERE:
        mbc_point_box(f, b->c, b->r, a);
        return 0;
    case MBC_BOX * 4 + MBC_CAPSULE:
        mbc_point_box(f, slot ? b->e1 : b->e0, b->r, a);
        return 0;
    case MBC_BOX * 4 + MBC_BOX:
        if (slot < 8) {
            mbc_corner(b, slot, p);
            mbc_point_box(f, p, 0.0, a);
        } else if (slot < 16) {
            mbc_corner(a, slot - 8, p);
            mbc_point_box(f, p, 0.0, b);
            mbc_swap(f);
        } else {
            mbc_edge_edge(f, a, b, (slot - 16) / 3, (slot - 16) % 3);
        }
        return 0;
    case MBC_CAPSULE * 4 + MBC_SPHERE:
        s = mbc_segment_parameter(a->e0, a->e1, b->c);
        for (int i = 0; i < 3; ++i) pa[i] = a->e0[i] + s * (a->e1[i] - a->e0[i]);
        mbc_line(f, pa, b->c, a->r, b->r, up);
        mbc_slide_axis(a->e0, a->e1, s, &f->sa, f->a);
        return 0;
    case MBC_CAPSULE * 4 + MBC_CAPSULE:
        mbc_closest(a->e0, a->e1, b->e0, b->e1, pa, pb, &s, &t);
        mbc_line(f, pa, pb, a->r, b->r, up);
        mbc_slide_axis(a->e0, a->e1, s, &f->sa, f->a);
        mbc_slide_axis(b->e0, b->e1, t, &f->sb, f->b);
        return 0;
    case MBC_SPHERE * 4 + MBC_SPHERE:
        mbc_line(f, a->c, b->c, a->r, b->r, up);
        return 0;
    default:
        return 1;
    }
}

/* velocity v, acceleration (at zero generalised acceleration) acc and angular velocity w of
   the material point p of body `body` (-1: the ground) */
static void mbc_motion(int body, const double *p, double *v, double *acc, double *w) {
    if (body < 0) {
        for (int i = 0; i < 3; ++i) v[i] = acc[i] = w[i] = 0.0;
        return;
    }
    const double *row = mbc_body(body), *V = row + 12, *A = row + 18;
    double t[3];
    for (int i = 0; i < 3; ++i) w[i] = V[i];
    mbc_cross(w, p, t);
    for (int i = 0; i < 3; ++i) v[i] = V[3 + i] + t[i];
    mbc_cross(A, p, t);
    for (int i = 0; i < 3; ++i) acc[i] = A[3 + i] + t[i];
    mbc_cross(w, v, t);
    for (int i = 0; i < 3; ++i) acc[i] += t[i];
}

/* The gap's acceleration at zero generalised acceleration (collide.turning_term plus
   n . (a_b - a_a)). */
static double mbc_bias(const mbc_feature *f, int ia, int ib) {
    double va[3], aa[3], wa[3], vb[3], ab[3], wb[3], dv[3], da[3], ta[3] = {0, 0, 0}, tb[3] = {0, 0, 0}, w[3];
    mbc_motion(ia, f->pa, va, aa, wa);
    mbc_motion(ib, f->pb, vb, ab, wb);
    for (int i = 0; i < 3; ++i) { dv[i] = vb[i] - va[i]; da[i] = ab[i] - aa[i]; w[i] = f->pb[i] - f->pa[i]; }
    const double *n = f->n;
    double value = mbc_dot(n, da);
    if (f->owner == MBC_OWNER_A || f->owner == MBC_OWNER_B) {
        double t[3];
        mbc_cross(f->owner == MBC_OWNER_A ? wa : wb, n, t);
        return value + 2.0 * mbc_dot(t, dv);
    }
    if (f->sa) mbc_cross(wa, f->a, ta);
    if (f->sb) mbc_cross(wb, f->b, tb);
    const double r1 = f->sa ? mbc_dot(dv, f->a) + mbc_dot(w, ta) : 0.0;
    const double r2 = f->sb ? mbc_dot(dv, f->b) + mbc_dot(w, tb) : 0.0;
    double sd = r1, td = -r2;
    if (f->sa && f->sb) {
        const double c = mbc_dot(f->a, f->b);
        if (1.0 - c * c < 1e-12) { sd = td = 0.0; }
        else { td = (c * r1 - r2) / (1.0 - c * c); sd = r1 + c * td; }
    }
    if (f->owner == MBC_OWNER_LINE) {
        double wd[3];
        for (int i = 0; i < 3; ++i) wd[i] = dv[i] - (f->sa ? sd * f->a[i] : 0.0) + (f->sb ? td * f->b[i] : 0.0);
        const double along = mbc_dot(n, wd);
        return value + (mbc_dot(wd, wd) - along * along) / (f->dist > 1e-12 ? f->dist : 1e-12)
            + 2.0 * td * mbc_dot(n, tb) - 2.0 * sd * mbc_dot(n, ta);
    }
    if (!(f->sa && f->sb)) return value;
    double u[3], uh[3], udot[3], x[3], ldot[3];
    mbc_cross(f->a, f->b, u);
    const double size = mbc_norm(u);
    for (int i = 0; i < 3; ++i) uh[i] = u[i] / size;
    mbc_cross(ta, f->b, udot);
    mbc_cross(f->a, tb, x);
    for (int i = 0; i < 3; ++i) udot[i] += x[i];
    const double sign = mbc_dot(n, u) >= 0.0 ? 1.0 : -1.0, along = mbc_dot(uh, udot);
    for (int i = 0; i < 3; ++i) ldot[i] = sign * (udot[i] - uh[i] * along) / size;
    return value + mbc_dot(ldot, dv) + td * mbc_dot(n, tb) - sd * mbc_dot(n, ta);
}

/* Feature k measured from the kinematics in mbc_kin; its entries' bodies in *ia, *ib. */
static int mbc_measure(long k, mbc_feature *f, int *ia, int *ib) {
    mbc_shape a, b;
    const long *ft = mbc_feat + 3 * k;
    mbc_place(ft[0], &a);
    mbc_place(ft[1], &b);
    *ia = a.body; *ib = b.body;
    return mbc_features(&a, &b, (int)ft[2], f);
}

/* Every candidate's gap, bias and Jacobian row at (q, qd) into the output buffer. */
void mb_collide_eval(const double *q, const double *qd, const double *p) {
    double u[1] = {0.0};
    if (!mbc_nc && !mbc_nw) return;
    kinematics(q, qd, p, u, mbc_kin);
    const double *cols = mbc_kin + KINEMATICS_COLUMNS_OFF;
    for (int c = 0; c < mbc_nc; ++c) {
        mbc_feature f;
        int ia, ib;
        double *out = mbc_out + (long)c * (MBC_OUT_HEAD + NQ), *J = out + MBC_OUT_HEAD;
        if (mbc_measure(mbc_cand[c], &f, &ia, &ib)) { out[0] = out[1] = NAN; continue; }
        out[0] = f.gap;
        out[1] = mbc_bias(&f, ia, ib);
        double xa[3], xb[3];
        mbc_cross(f.pa, f.n, xa);
        mbc_cross(f.pb, f.n, xb);
        const double *ma = ia < 0 ? 0 : mbc_mask + (long)ia * NQ, *mb = ib < 0 ? 0 : mbc_mask + (long)ib * NQ;
        for (int k = 0; k < NQ; ++k) {
            const double *W = cols + 6 * k, *V0 = W + 3;
            const double nv0 = mbc_dot(f.n, V0);
            J[k] = (mb ? mb[k] * (nv0 + mbc_dot(xb, W)) : 0.0) - (ma ? ma[k] * (nv0 + mbc_dot(xa, W)) : 0.0);
        }
    }
}

/* Feature k's gap (m) from the last mb_collide_eval; NaN when it is not a candidate. */
double mb_collide_gap_of(long k) {
    const long c = (k >= 0 && k < mbc_nf) ? mbc_slot[k] : -1;
    return c < 0 ? NAN : mbc_out[c * (MBC_OUT_HEAD + NQ)];
}

/* Feature k's gap, Jacobian row (NQ) and bias from the last mb_collide_eval (1: not a
   candidate, the row is left unchanged). */
int mb_collide_row(long k, double *g, double *J, double *bias) {
    const long c = (k >= 0 && k < mbc_nf) ? mbc_slot[k] : -1;
    if (c < 0) return 1;
    const double *out = mbc_out + c * (MBC_OUT_HEAD + NQ);
    *g = out[0];
    *bias = out[1];
    for (int i = 0; i < NQ; ++i) J[i] = out[MBC_OUT_HEAD + i];
    return 0;
}

/* Feature k's exact gap (m) at (q, qd) on its own (any feature; NaN when k is unknown). */
double mb_collide_gap(long k, const double *q, const double *qd, const double *p) {
    double u[1] = {0.0};
    mbc_feature f;
    int ia, ib;
    if (k < 0 || k >= mbc_nf) return NAN;
    kinematics(q, qd, p, u, mbc_kin);
    return mbc_measure(k, &f, &ia, &ib) ? NAN : f.gap;
}

/* 1 when the state of the last mb_collide_eval leaves what the stretch was configured for:
   a watched shape drifted farther than mbc_drift from its start, or the two fastest ones
   move faster together than mbc_ceiling. */
int mb_collide_leaves(void) {
    double first = 0.0, second = 0.0;
    for (int k = 0; k < mbc_nw; ++k) {
        mbc_shape s;
        double v[3], acc[3], w[3], d[3];
        mbc_place(mbc_went[k], &s);
        for (int i = 0; i < 3; ++i) d[i] = s.c[i] - mbc_wcentre[3 * k + i];
        if (mbc_dot(d, d) > mbc_drift * mbc_drift) return 1;
        mbc_motion(s.body, s.c, v, acc, w);
        const double speed = mbc_norm(v) + mbc_norm(w) * mbc_wradius[k];
        if (speed > first) { second = first; first = speed; }
        else if (speed > second) second = speed;
    }
    return first + second > mbc_ceiling;
}
