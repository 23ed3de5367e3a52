/* servobus C core: the byte work under the Python layers.
 *
 * This header is also the cffi cdef (read by src/servobus/_build_core.py), so it stays parsable by
 * cffi: no #include, no macros other than integer constants, no function bodies. The .c files
 * include sb_internal.h, which brings <stdint.h>/<stddef.h> in first.
 *
 * Every function is pure over caller-owned buffers: input pointer + length, output arrays from the
 * caller, an int count or status back. No malloc, no globals (tables are static const), no Python.
 * Every function checks its arguments (NULL with a non-zero length, capacities, field scales,
 * layouts and kinds) and returns a status for a bad one: nothing here trusts the caller.
 */

/* Bumped whenever a signature or struct below changes; the wrapper refuses another value. */
#define SB_CORE_ABI 2

/* ---- status codes (mapped to exceptions in one table: servobus/codec/_lib.py) ---- */
#define SB_OK 0
#define SB_E_RANGE -1    /* a value lies outside its field's [lo, hi] */
#define SB_E_NAN -2      /* a value is NaN */
#define SB_E_LAYOUT -3   /* unknown layout or deframer kind */
#define SB_E_ARG -4      /* bad pointer, size, capacity, stride, field scale, flag or option */

/* Compiled-in package version, compared at import with servobus.__version__. */
const char *sb_core_version(void);
/* SB_CORE_ABI as compiled, compared at import with the wrapper's own number. */
int sb_core_abi(void);

/* ---- CRC (crc.c) ----
 * CRC-16/MODBUS: reflected poly 0xA001, init 0xFFFF, no final xor. Pass 0xFFFF to start, or a
 * previous result to continue over more data. Sent low byte first.
 * CRC-32/ISO-HDLC (zlib, IEEE 802.3): same chaining convention as zlib.crc32: start with 0.
 * Both return the CRC (never negative), or SB_E_ARG for data NULL with len > 0: the return types are
 * wider than the CRCs so that a status fits beside them. */
int32_t sb_crc16_modbus(const char *data, size_t len, uint16_t crc);
int64_t sb_crc32_ieee(const char *data, size_t len, uint32_t crc);

/* ---- field scaling and bit packing (bitpack.c) ----
 * A field maps a physical value x to an integer code:
 *     code = round_half_away((x - origin) * codes / span)     (exactly this order of operations)
 *     x    = code * span / codes + origin
 * Packing first checks lo <= x <= hi (NaN always fails; with SB_PACK_SATURATE, x is clamped into
 * [lo, hi] instead), then clamps the code into the field's bit width, which only matters at the top
 * of offset-binary fields where +full scale is one code past the last (hollow manual §4.3).
 * A field must have finite members, lo <= hi, and codes > 0, span > 0 (SB_E_ARG otherwise). */
typedef struct {
    double lo;      /* smallest accepted physical value */
    double hi;      /* largest accepted physical value */
    double origin;  /* physical value of code 0 */
    double codes;   /* `span` physical units are `codes` codes */
    double span;
} sb_field;

/* Where a pack failed: frame index within the batch, field index within the layout, the value. */
typedef struct {
    size_t frame;
    int field;
    double value;
} sb_pack_error;

#define SB_PACK_SATURATE 1  /* the only flag; any other bit is SB_E_ARG */

/* Frame layouts. Fields are listed in the order of the `values` rows (the layout's field order). */
#define SB_LAYOUT_MIT_COMMAND 1        /* 8 B: p u16, v u12, kp u12, kd u12, t u12 (big-endian bits) */
#define SB_LAYOUT_HOLLOW_SETPOINT 2    /* as MIT_COMMAND, but never emits FF x7 + F9..FE (a special command) */
#define SB_LAYOUT_MIT_REPLY 3          /* 6 B: id u8, p u16, v u12, t u12 */
#define SB_LAYOUT_HOLLOW_EXT_REPLY 4   /* 8 B: id u8, x s32 (bytes 1-2 = x[15:0], 6-7 = x[31:16]), v u12, t u12 */
#define SB_LAYOUT_HOLLOW_FD_COMMAND 5  /* 16 B: pos s40, vel s32, cur s16, mode u8, run u8, kp u8, kd u8, zero u8 */
#define SB_LAYOUT_HOLLOW_FD_REPLY 6    /* 16 B: pos s40, vel s32, cur s16, mode u8, run u8, reserved u8, temp s8, slave u8 */
#define SB_LAYOUT_COUNT 6

/* Bytes a layout occupies (0 for an unknown layout), and its number of fields. */
int sb_layout_size(int layout);
int sb_layout_fields(int layout);
/* Width in bits of field `field` (negative for a signed field), 0 when out of range. */
int sb_layout_field_bits(int layout, int field);

/* Pack n frames. values: n rows of sb_layout_fields() doubles. out: out_cap bytes, at least
 * n * stride; bytes past the layout size in each slot are zeroed. Returns SB_OK; SB_E_LAYOUT for an
 * unknown layout; SB_E_ARG for a NULL pointer (when n > 0), stride < layout size, out_cap too small,
 * a bad field or an unknown flag; SB_E_RANGE / SB_E_NAN with *err filled (err may be NULL). After an
 * error the output is undefined (the caller sends nothing). */
int sb_pack(int layout, const sb_field *fields, const double *values, size_t n, size_t stride,
            int flags, uint8_t *out, size_t out_cap, sb_pack_error *err);

/* Unpack n frames laid out every `stride` bytes into n rows of doubles; values holds values_cap
 * doubles, at least n * sb_layout_fields(). Every bit pattern decodes. Errors as sb_pack (no
 * SB_E_RANGE / SB_E_NAN). */
int sb_unpack(int layout, const sb_field *fields, const uint8_t *frames, size_t n, size_t stride,
              double *values, size_t values_cap);

/* ---- incremental stream de-framers (deframe.c) ----
 * Fed bytes in any chunking, they return whole frames. Bytes that cannot start a valid frame are
 * dropped one at a time and counted (discarded_bytes); a frame whose check fails where a frame was
 * expected (stream start, or right after a good frame) counts once in crc_errors, then the
 * de-framer hunts byte by byte for the next frame that checks. Memory is the fixed buffer below. */
#define SB_DEFRAME_CAPACITY 1024

#define SB_DEFRAME_MYACTUATOR_RS485 1  /* 0x3E, ID, LEN, DATA[LEN], CRC16 lo, hi; option = max LEN (1..255) */
#define SB_DEFRAME_HOLLOW_TRANSPARENT 2 /* ID, 16 bytes, CRC32 LSB first (21 bytes, no header); option 0 */
#define SB_DEFRAME_MODBUS_RTU 3         /* functions 0x03/0x10 and their exceptions; option = direction mask */

#define SB_MODBUS_REQUESTS 1
#define SB_MODBUS_REPLIES 2

#define SB_TRANSPARENT_FRAME 21
#define SB_MODBUS_MAX_FRAME 255         /* 5 + 250 (0x03 reply) = 9 + 246 (0x10 request) */

typedef struct {
    int kind;
    int option;
    int synced;               /* 1 when the next byte is where a frame should start */
    size_t len;               /* bytes held in buf */
    uint64_t frames;
    uint64_t discarded_bytes;
    uint64_t crc_errors;
    uint8_t buf[SB_DEFRAME_CAPACITY];
} sb_deframer;

/* Returns SB_OK, SB_E_LAYOUT for an unknown kind, SB_E_ARG for a bad option or d NULL. After an
 * error the state is zeroed, and every other function refuses it. */
int sb_deframer_init(sb_deframer *d, int kind, int option);

/* Largest frame this de-framer can return; 0 when d is NULL or not a valid de-framer. */
size_t sb_deframer_max_frame(const sb_deframer *d);

/* Drop the buffered bytes (they count as discarded) and expect a frame at the next byte. Returns
 * SB_OK, or SB_E_LAYOUT / SB_E_ARG for an invalid de-framer. */
int sb_deframer_reset(sb_deframer *d);

/* Consume input and write whole frames back to back into out, their lengths into lens. Stops when
 * the input is used up and nothing more parses, or when out/lens cannot take another frame of the
 * maximum size. *consumed tells how much input was taken (taken bytes are held internally); call
 * again with the rest. Returns the number of frames written (at most INT_MAX), or a negative status:
 * SB_E_LAYOUT / SB_E_ARG for an invalid de-framer, SB_E_ARG for a NULL pointer (data may be NULL
 * when len is 0), out_cap below sb_deframer_max_frame() or max_frames 0, which could never make
 * progress. *consumed is 0 after an error. */
int sb_deframer_feed(sb_deframer *d, const char *data, size_t len, size_t *consumed,
                     uint8_t *out, size_t out_cap, uint16_t *lens, size_t max_frames);

/* The line has been quiet long enough that no frame is still arriving (Modbus RTU: 3.5 characters).
 * Frames the buffer holds are returned; a candidate still waiting for bytes is dropped byte by byte
 * as noise, so one stray byte cannot hold back the frame behind it until more traffic comes. Stops
 * early, like feed, when out/lens are full; returns the number of frames written or a negative
 * status, as feed. */
int sb_deframer_idle(sb_deframer *d, uint8_t *out, size_t out_cap, uint16_t *lens, size_t max_frames);

/* ---- SLCAN (LAWICEL) receive lines (slcan.c) ----
 * What a USB-CAN adapter speaking LAWICEL sends its host, cut at CR and checked. Frame lines:
 *   tiiiL<data>     standard, 3 hex id digits (<= 0x7FF), DLC 0..8, 2 hex digits per data byte
 *   TiiiiiiiiL<data> extended, 8 hex id digits (<= 0x1FFFFFFF)
 *   riiiL, RiiiiiiiiL remote (no data): counted in `remote` and dropped (servobus carries no RTR)
 *   d/D, b/B        CAN FD as t/T (b/B: bit-rate switch), DLC code 0..F for 0..8,12,16,20,24,32,48,64
 * With SB_SLCAN_TIMESTAMPS (the adapter was sent Z1) every frame line ends in exactly 4 hex digits
 * of timestamp; without it, none. Hex digits may be either case. The number of data digits must be
 * exactly what the DLC says, or the line is malformed: never truncated, never padded.
 * Other lines: an empty line (the adapter's OK, a bare CR) counts in `oks`; `z`/`Z` (transmit
 * acknowledgements) in `acks`; anything else is malformed. BEL (0x07, the adapter's error reply)
 * ends a line by itself: it counts in `bells`, and an unfinished line before it is malformed. A LF
 * at the start of a line is skipped (CR LF adapters). A line longer than the longest valid one
 * counts once in `overlong` and is dropped up to its CR (or BEL): its bytes are never held.
 * Every byte of a malformed or over-long line, its terminating CR included, counts in
 * discarded_bytes. Memory is the fixed line buffer below, whatever the input. */
#define SB_SLCAN_TIMESTAMPS 1        /* the only option bit */
#define SB_SLCAN_MAX_LINE 142        /* longest valid line before its CR: D + 8 + 1 + 128 + 4 timestamp */
#define SB_SLCAN_MAX_DATA 64

#define SB_SLCAN_EXTENDED 1          /* sb_slcan_frame.flags */
#define SB_SLCAN_FD 2
#define SB_SLCAN_BRS 4

typedef struct {
    uint32_t id;
    uint8_t flags;            /* SB_SLCAN_EXTENDED | SB_SLCAN_FD | SB_SLCAN_BRS */
    uint8_t len;              /* data bytes, 0..64 */
    uint16_t timestamp;       /* the line's timestamp suffix (SB_SLCAN_TIMESTAMPS), else 0 */
    uint8_t data[SB_SLCAN_MAX_DATA];
} sb_slcan_frame;

typedef struct {
    int option;
    int dropping;             /* 1 while the rest of an over-long line is dropped up to its CR */
    size_t len;               /* bytes of the current line held in line */
    uint64_t frames;          /* data frames returned */
    uint64_t remote;          /* remote frames (counted, not returned) */
    uint64_t acks;            /* z/Z lines */
    uint64_t oks;             /* empty lines */
    uint64_t bells;           /* BEL bytes */
    uint64_t malformed;       /* lines dropped as malformed (bad form, hex, id, DLC, length; unknown) */
    uint64_t overlong;        /* lines dropped as longer than the longest valid line */
    uint64_t discarded_bytes; /* bytes of malformed and over-long lines, their CR included */
    uint8_t line[SB_SLCAN_MAX_LINE];
} sb_slcan;

/* Returns SB_OK, or SB_E_ARG for s NULL or an unknown option bit (the state is then zeroed, and
 * every other function refuses it). */
int sb_slcan_init(sb_slcan *s, int option);

/* Longest line (before its CR) this state accepts: 138, or 142 with SB_SLCAN_TIMESTAMPS; 0 for an
 * invalid state. */
size_t sb_slcan_max_line(const sb_slcan *s);

/* Drop the line held so far (its bytes count as discarded) and start at a line boundary. Returns
 * SB_OK or SB_E_ARG for an invalid state. */
int sb_slcan_reset(sb_slcan *s);

/* Consume input and write the data frames it completes into out[0 .. max_frames). Stops after the
 * input is used up or right after the frame that fills out; *consumed tells how much input was
 * taken (call again with the rest). Returns the number of frames written (at most INT_MAX), or
 * SB_E_ARG for an invalid state, a NULL pointer (data may be NULL when len is 0) or max_frames 0;
 * *consumed is 0 after an error. */
int sb_slcan_feed(sb_slcan *s, const char *data, size_t len, size_t *consumed, sb_slcan_frame *out,
                  size_t max_frames);

/* ---- precise timer (timer.c) ----
 * The exception to "no system calls" above: a CLOCK_MONOTONIC timer an event loop can wait on, for
 * the pacer (servobus/ticks.py) to sleep to a deadline without spinning. On Linux a timerfd, created
 * non-blocking and close-on-exec; the caller owns the descriptor and closes it (os.close). It reads
 * as ready once its deadline has passed, until sb_timer_clear. Elsewhere every function returns
 * SB_E_UNSUPPORTED. System errors return SB_E_OS with errno in *err (err may be NULL). */
#define SB_E_OS -5           /* a system call failed: errno in *err */
#define SB_E_UNSUPPORTED -6  /* no such timer on this platform */

/* A new timer (disarmed): its descriptor (>= 0), SB_E_OS or SB_E_UNSUPPORTED. */
int sb_timer_open(int *err);
/* Arm it at an ABSOLUTE CLOCK_MONOTONIC time in ns (TFD_TIMER_ABSTIME), replacing any earlier
 * deadline and dropping an expiry not yet cleared; a deadline already passed (0 included) expires
 * at once. SB_OK, SB_E_ARG for fd < 0 or deadline_ns < 0, SB_E_OS, SB_E_UNSUPPORTED. */
int sb_timer_arm(int fd, int64_t deadline_ns, int *err);
/* Disarm it, dropping an expiry not yet cleared. SB_OK, SB_E_ARG, SB_E_OS, SB_E_UNSUPPORTED. */
int sb_timer_disarm(int fd, int *err);
/* Clear its expiry (read): how many deadlines expired since the last clear (>= 1), 0 when none has
 * (it does not block), or SB_E_ARG / SB_E_OS / SB_E_UNSUPPORTED. */
int64_t sb_timer_clear(int fd, int *err);
/* CLOCK_MONOTONIC now, in ns (the clock sb_timer_arm takes; time.monotonic_ns() reads the same on
 * Linux), or SB_E_UNSUPPORTED. */
int64_t sb_timer_now_ns(void);
