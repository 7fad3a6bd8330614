/*
 * capture_check: a small V4L2 probe for the vivid test VM (scripts/test-v4l2-vm.sh).
 * Built on the host (gcc -static) and run inside the guest. No dependency but libc.
 *
 *   capture_check list [DEV...]                  nodes: driver, caps, inputs/outputs, formats,
 *                                                 sizes, intervals (default: every /dev/video*)
 *   capture_check capture DEV FOURCC W H [N] [FILE]
 *                                                 stream N (5) mmap frames: size, sequence,
 *                                                 timestamp, flags; fails unless timestamps are
 *                                                 flagged MONOTONIC and increase, and (with FILE)
 *                                                 unless every frame equals one of FILE's
 *   capture_check loop OUT CAP FOURCC W H [N] [FILE]
 *                                                 vivid output -> capture loop: writes known
 *                                                 frames (from FILE: raw frames of the set size,
 *                                                 used round-robin; default a generated
 *                                                 pattern) into OUT, reads N (5) frames from CAP
 *                                                 and compares them byte for byte with what was
 *                                                 written; exit 0 only when every frame matches
 *   capture_check feed OUT CAP FOURCC W H FILE [SECONDS]
 *                                                 prepares CAP for the loop (HDMI input, DV
 *                                                 timings, format, OSD text off, Loop Video
 *                                                 on), closes it and
 *                                                 keeps writing FILE's frames into OUT (forever,
 *                                                 or SECONDS), so another program (deard) can
 *                                                 capture them from CAP. Prints "feeding ..."
 *                                                 once OUT streams: from then on every CAP
 *                                                 frame is a copy of a fed one (vivid keeps
 *                                                 the last queued output buffer until another
 *                                                 is queued; NBUF are kept queued, paced by
 *                                                 vivid's output rate). CAP must not be
 *                                                 streaming in another process yet (EBUSY)
 *
 * FOURCC is four characters, padded with spaces ("Y16 ", "GREY", "YUYV"); W x H must be a CEA/DMT
 * DV timing size vivid knows for the loop (640x480 is; the loop sets both HDMI ends to it).
 * The loop's procedure and what it gives: the comment at the top of scripts/test-v4l2-vm.sh.
 * Exit status: 0 success, 1 a check failed, 2 usage or a V4L2 call failed.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <glob.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define NBUF 4

static int xioctl(int fd, unsigned long req, void *arg)
{
	int r;
	do
		r = ioctl(fd, req, arg);
	while (r == -1 && errno == EINTR);
	return r;
}

static void die(const char *what)
{
	fprintf(stderr, "capture_check: %s: %s%s\n", what, strerror(errno),
		errno == EBUSY ? " (another process streams the node: set the loop up before a"
				 " capturer opens it)"
			       : "");
	exit(2);
}

static void fcc(uint32_t f, char out[5])
{
	for (int i = 0; i < 4; i++) {
		char c = (char)((f >> (8 * i)) & 0xff);
		out[i] = (c >= 32 && c < 127) ? c : '?';
	}
	out[4] = 0;
}

static uint32_t parse_fcc(const char *s)
{
	char b[4] = {' ', ' ', ' ', ' '};
	for (int i = 0; i < 4 && s[i]; i++)
		b[i] = s[i];
	return v4l2_fourcc(b[0], b[1], b[2], b[3]);
}

static double mono_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return ts.tv_sec + ts.tv_nsec / 1e9;
}

/* ---------------------------------------------------------------- list */

/* Formats, one line each; the sizes and intervals are printed for the first format and then
 * only where they differ from the previous format's. */
static void list_formats(int fd, enum v4l2_buf_type type, const char *label)
{
	static char prev[8192], cur[8192];
	prev[0] = 0;
	struct v4l2_fmtdesc fd_ = {.type = type};
	for (fd_.index = 0; xioctl(fd, VIDIOC_ENUM_FMT, &fd_) == 0; fd_.index++) {
		char f[5];
		size_t n = 0;
		cur[0] = 0;
#define ADD(...)                                                                                   \
	do {                                                                                       \
		if (n < sizeof cur)                                                                \
			n += (size_t)snprintf(cur + n, sizeof cur - n, __VA_ARGS__);               \
	} while (0)
		fcc(fd_.pixelformat, f);
		struct v4l2_frmsizeenum fs = {.pixel_format = fd_.pixelformat};
		for (fs.index = 0; xioctl(fd, VIDIOC_ENUM_FRAMESIZES, &fs) == 0; fs.index++) {
			if (fs.type == V4L2_FRMSIZE_TYPE_DISCRETE) {
				ADD(" %ux%u@", fs.discrete.width, fs.discrete.height);
				struct v4l2_frmivalenum fi = {.pixel_format = fd_.pixelformat,
							      .width = fs.discrete.width,
							      .height = fs.discrete.height};
				for (fi.index = 0; xioctl(fd, VIDIOC_ENUM_FRAMEINTERVALS, &fi) == 0;
				     fi.index++) {
					if (fi.type != V4L2_FRMIVAL_TYPE_DISCRETE) {
						ADD("(stepwise)");
						break;
					}
					ADD("%s%u/%u", fi.index ? "," : "", fi.discrete.numerator,
					    fi.discrete.denominator);
				}
			} else {
				ADD(" %ux%u..%ux%u step %u/%u", fs.stepwise.min_width,
				    fs.stepwise.min_height, fs.stepwise.max_width,
				    fs.stepwise.max_height, fs.stepwise.step_width,
				    fs.stepwise.step_height);
				break;
			}
		}
		if (fs.index == 0)
			ADD(" (no ENUM_FRAMESIZES: any size the current input/output allows)");
#undef ADD
		if (!strcmp(cur, prev))
			printf("  %s format '%s' %s: same sizes\n", label, f, (char *)fd_.description);
		else
			printf("  %s format '%s' %s:%s\n", label, f, (char *)fd_.description, cur);
		memcpy(prev, cur, sizeof prev);
	}
}

static void list_current(int fd, enum v4l2_buf_type type, const char *label)
{
	struct v4l2_format fmt = {.type = type};
	if (xioctl(fd, VIDIOC_G_FMT, &fmt) == 0) {
		char f[5];
		fcc(fmt.fmt.pix.pixelformat, f);
		printf("  current %s format '%s' %ux%u bytesperline %u sizeimage %u field %u\n", label,
		       f, fmt.fmt.pix.width, fmt.fmt.pix.height, fmt.fmt.pix.bytesperline,
		       fmt.fmt.pix.sizeimage, fmt.fmt.pix.field);
	}
}

static void list_one(const char *dev)
{
	int fd = open(dev, O_RDWR);
	if (fd < 0) {
		printf("%s: open: %s\n", dev, strerror(errno));
		return;
	}
	struct v4l2_capability cap;
	if (xioctl(fd, VIDIOC_QUERYCAP, &cap) < 0) {
		printf("%s: QUERYCAP: %s\n", dev, strerror(errno));
		close(fd);
		return;
	}
	uint32_t c = (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
	printf("%s: driver %s card '%s' bus %s caps 0x%08x%s%s%s%s%s%s\n", dev, cap.driver, cap.card,
	       cap.bus_info, c, (c & V4L2_CAP_VIDEO_CAPTURE) ? " video-capture" : "",
	       (c & V4L2_CAP_VIDEO_OUTPUT) ? " video-output" : "",
	       (c & V4L2_CAP_VIDEO_CAPTURE_MPLANE) ? " capture-mplane" : "",
	       (c & V4L2_CAP_VIDEO_OUTPUT_MPLANE) ? " output-mplane" : "",
	       (c & (V4L2_CAP_VBI_CAPTURE | V4L2_CAP_SLICED_VBI_CAPTURE | V4L2_CAP_VBI_OUTPUT |
		     V4L2_CAP_SLICED_VBI_OUTPUT))
		       ? " vbi"
		       : "",
	       (c & V4L2_CAP_META_CAPTURE) ? " meta-capture" : "");
	struct v4l2_input in = {0};
	for (in.index = 0; xioctl(fd, VIDIOC_ENUMINPUT, &in) == 0; in.index++)
		printf("  input %u '%s' type %u\n", in.index, in.name, in.type);
	struct v4l2_output out = {0};
	for (out.index = 0; xioctl(fd, VIDIOC_ENUMOUTPUT, &out) == 0; out.index++)
		printf("  output %u '%s' type %u\n", out.index, out.name, out.type);
	if (c & V4L2_CAP_VIDEO_CAPTURE) {
		list_current(fd, V4L2_BUF_TYPE_VIDEO_CAPTURE, "capture");
		list_formats(fd, V4L2_BUF_TYPE_VIDEO_CAPTURE, "capture");
	}
	if (c & V4L2_CAP_VIDEO_OUTPUT) {
		list_current(fd, V4L2_BUF_TYPE_VIDEO_OUTPUT, "output");
		list_formats(fd, V4L2_BUF_TYPE_VIDEO_OUTPUT, "output");
	}
	close(fd);
}

static int cmd_list(int argc, char **argv)
{
	if (argc > 0) {
		for (int i = 0; i < argc; i++)
			list_one(argv[i]);
		return 0;
	}
	glob_t g;
	if (glob("/dev/video*", 0, NULL, &g) != 0) {
		printf("no /dev/video* nodes\n");
		return 1;
	}
	for (size_t i = 0; i < g.gl_pathc; i++)
		list_one(g.gl_pathv[i]);
	globfree(&g);
	return 0;
}

/* ---------------------------------------------------------------- streaming helpers */

struct stream {
	int fd;
	enum v4l2_buf_type type;
	struct v4l2_format fmt;
	void *mem[NBUF];
	size_t len[NBUF];
	unsigned n;
};

static void set_fmt(struct stream *s, uint32_t fourcc, unsigned w, unsigned h)
{
	memset(&s->fmt, 0, sizeof s->fmt);
	s->fmt.type = s->type;
	s->fmt.fmt.pix.width = w;
	s->fmt.fmt.pix.height = h;
	s->fmt.fmt.pix.pixelformat = fourcc;
	s->fmt.fmt.pix.field = V4L2_FIELD_NONE;
	if (xioctl(s->fd, VIDIOC_S_FMT, &s->fmt) < 0)
		die("VIDIOC_S_FMT");
	char want[5], got[5];
	fcc(fourcc, want);
	fcc(s->fmt.fmt.pix.pixelformat, got);
	printf("%s format: '%s' %ux%u bytesperline %u sizeimage %u field %u\n",
	       s->type == V4L2_BUF_TYPE_VIDEO_CAPTURE ? "capture" : "output", got,
	       s->fmt.fmt.pix.width, s->fmt.fmt.pix.height, s->fmt.fmt.pix.bytesperline,
	       s->fmt.fmt.pix.sizeimage, s->fmt.fmt.pix.field);
	if (s->fmt.fmt.pix.pixelformat != fourcc || s->fmt.fmt.pix.width != w ||
	    s->fmt.fmt.pix.height != h) {
		fprintf(stderr, "capture_check: the driver changed the format to '%s' %ux%u (asked '%s' %ux%u)\n",
			got, s->fmt.fmt.pix.width, s->fmt.fmt.pix.height, want, w, h);
		exit(2);
	}
}

static void map_bufs(struct stream *s)
{
	struct v4l2_requestbuffers rb = {.count = NBUF, .type = s->type, .memory = V4L2_MEMORY_MMAP};
	if (xioctl(s->fd, VIDIOC_REQBUFS, &rb) < 0)
		die("VIDIOC_REQBUFS");
	s->n = rb.count < NBUF ? rb.count : NBUF;
	for (unsigned i = 0; i < s->n; i++) {
		struct v4l2_buffer b = {.type = s->type, .memory = V4L2_MEMORY_MMAP, .index = i};
		if (xioctl(s->fd, VIDIOC_QUERYBUF, &b) < 0)
			die("VIDIOC_QUERYBUF");
		s->len[i] = b.length;
		s->mem[i] = mmap(NULL, b.length, PROT_READ | PROT_WRITE, MAP_SHARED, s->fd, b.m.offset);
		if (s->mem[i] == MAP_FAILED)
			die("mmap");
	}
}

static void qbuf(struct stream *s, unsigned i, size_t bytesused)
{
	struct v4l2_buffer b = {.type = s->type, .memory = V4L2_MEMORY_MMAP, .index = i};
	if (s->type == V4L2_BUF_TYPE_VIDEO_OUTPUT) {
		b.bytesused = (uint32_t)bytesused;
		b.field = V4L2_FIELD_NONE;
	}
	if (xioctl(s->fd, VIDIOC_QBUF, &b) < 0)
		die("VIDIOC_QBUF");
}

static void streamon(struct stream *s)
{
	int t = s->type;
	if (xioctl(s->fd, VIDIOC_STREAMON, &t) < 0)
		die("VIDIOC_STREAMON");
}

static void streamoff(struct stream *s)
{
	int t = s->type;
	xioctl(s->fd, VIDIOC_STREAMOFF, &t);
}

/* Waits for one buffer; returns 0 and fills *b, or -1 on timeout. */
static int dqbuf(struct stream *s, struct v4l2_buffer *b, int timeout_ms)
{
	struct pollfd p = {.fd = s->fd,
			   .events = s->type == V4L2_BUF_TYPE_VIDEO_CAPTURE ? POLLIN : POLLOUT};
	int r = poll(&p, 1, timeout_ms);
	if (r < 0)
		die("poll");
	if (r == 0)
		return -1;
	memset(b, 0, sizeof *b);
	b->type = s->type;
	b->memory = V4L2_MEMORY_MMAP;
	if (xioctl(s->fd, VIDIOC_DQBUF, b) < 0)
		die("VIDIOC_DQBUF");
	return 0;
}

static void print_buf(const struct v4l2_buffer *b, double t0)
{
	uint32_t tsf = b->flags & V4L2_BUF_FLAG_TIMESTAMP_MASK;
	uint32_t src = b->flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK;
	printf("frame seq %u index %u bytesused %u timestamp %ld.%06ld flags 0x%08x (%s, %s%s) at +%.3f s\n",
	       b->sequence, b->index, b->bytesused, (long)b->timestamp.tv_sec,
	       (long)b->timestamp.tv_usec, b->flags,
	       tsf == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC ? "MONOTONIC"
	       : tsf == V4L2_BUF_FLAG_TIMESTAMP_COPY   ? "COPY"
						       : "UNKNOWN",
	       src == V4L2_BUF_FLAG_TSTAMP_SRC_SOE ? "start-of-exposure" : "end-of-frame",
	       (b->flags & V4L2_BUF_FLAG_ERROR) ? ", ERROR" : "", mono_now() - t0);
}

static int open_dev(const char *dev)
{
	int fd = open(dev, O_RDWR);
	if (fd < 0) {
		fprintf(stderr, "capture_check: open %s: %s\n", dev, strerror(errno));
		exit(2);
	}
	return fd;
}

/* ---------------------------------------------------------------- capture */

struct frames {
	uint8_t *data;
	size_t size; /* of one frame */
	unsigned count;
};
static void load_frames(struct frames *f, const char *file, size_t size, unsigned gen_count);
static int match_frame(const uint8_t *a, size_t bytesused, const struct frames *f);

static int cmd_capture(const char *dev, uint32_t fourcc, unsigned w, unsigned h, unsigned n,
		       const char *file)
{
	struct stream s = {.fd = open_dev(dev), .type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
	set_fmt(&s, fourcc, w, h);
	struct v4l2_streamparm parm = {.type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
	if (xioctl(s.fd, VIDIOC_G_PARM, &parm) == 0)
		printf("frame interval %u/%u s\n", parm.parm.capture.timeperframe.numerator,
		       parm.parm.capture.timeperframe.denominator);
	struct frames f = {0};
	unsigned match = 0;
	if (file)
		load_frames(&f, file, s.fmt.fmt.pix.sizeimage, 0);
	map_bufs(&s);
	for (unsigned i = 0; i < s.n; i++)
		qbuf(&s, i, 0);
	double t0 = mono_now();
	streamon(&s);
	int ok = 1;
	long long last_us = -1;
	for (unsigned k = 0; k < n; k++) {
		struct v4l2_buffer b;
		if (dqbuf(&s, &b, 10000) < 0) {
			fprintf(stderr, "capture_check: no frame from %s in 10 s\n", dev);
			return 1;
		}
		print_buf(&b, t0);
		long long us = (long long)b.timestamp.tv_sec * 1000000 + b.timestamp.tv_usec;
		if ((b.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) != V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC) {
			printf("FAIL: frame %u not flagged V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC\n", k);
			ok = 0;
		}
		if (us <= last_us) {
			printf("FAIL: timestamps do not increase\n");
			ok = 0;
		}
		if (b.bytesused != s.fmt.fmt.pix.sizeimage) {
			printf("FAIL: bytesused %u != sizeimage %u\n", b.bytesused, s.fmt.fmt.pix.sizeimage);
			ok = 0;
		}
		last_us = us;
		if (file)
			match += match_frame(s.mem[b.index], b.bytesused, &f);
		qbuf(&s, b.index, 0);
	}
	streamoff(&s);
	if (file) {
		printf("capture %s: %u of %u frames equal a frame of %s\n", dev, match, n, file);
		if (match != n)
			ok = 0;
	}
	printf("capture %s: %s\n", dev, ok ? "OK" : "FAILED");
	return ok ? 0 : 1;
}

/* ---------------------------------------------------------------- loop */

/* Selects the first input (capture) or output whose name starts with "HDMI". */
static void select_hdmi(int fd, int output)
{
	if (output) {
		struct v4l2_output o = {0};
		for (o.index = 0; xioctl(fd, VIDIOC_ENUMOUTPUT, &o) == 0; o.index++)
			if (!strncmp((char *)o.name, "HDMI", 4)) {
				int i = (int)o.index;
				if (xioctl(fd, VIDIOC_S_OUTPUT, &i) < 0)
					die("VIDIOC_S_OUTPUT");
				printf("output %d '%s'\n", i, o.name);
				return;
			}
	} else {
		struct v4l2_input in = {0};
		for (in.index = 0; xioctl(fd, VIDIOC_ENUMINPUT, &in) == 0; in.index++)
			if (!strncmp((char *)in.name, "HDMI", 4)) {
				int i = (int)in.index;
				if (xioctl(fd, VIDIOC_S_INPUT, &i) < 0)
					die("VIDIOC_S_INPUT");
				printf("input %d '%s'\n", i, in.name);
				return;
			}
	}
	fprintf(stderr, "capture_check: no HDMI %s (vivid's input_types/output_types)\n",
		output ? "output" : "input");
	exit(2);
}

/* Sets the DV timings of the current HDMI input/output to the first preset of size w x h. */
static void set_timings(int fd, unsigned w, unsigned h, const char *label)
{
	struct v4l2_enum_dv_timings e = {0};
	for (e.index = 0; xioctl(fd, VIDIOC_ENUM_DV_TIMINGS, &e) == 0; e.index++) {
		if (e.timings.bt.width == w && e.timings.bt.height == h && !e.timings.bt.interlaced) {
			if (xioctl(fd, VIDIOC_S_DV_TIMINGS, &e.timings) < 0)
				die("VIDIOC_S_DV_TIMINGS");
			uint64_t tot = (uint64_t)V4L2_DV_BT_FRAME_WIDTH(&e.timings.bt) *
				       V4L2_DV_BT_FRAME_HEIGHT(&e.timings.bt);
			printf("%s DV timings %ux%u pixelclock %llu (%.2f fps)\n", label, w, h,
			       (unsigned long long)e.timings.bt.pixelclock,
			       tot ? (double)e.timings.bt.pixelclock / (double)tot : 0.0);
			return;
		}
	}
	fprintf(stderr, "capture_check: %s: no progressive DV timing of %ux%u\n", label, w, h);
	exit(2);
}

/* Finds a control by name (vivid's private IDs moved between kernel versions). */
static int set_ctrl_by_name(int fd, const char *name, int value)
{
	struct v4l2_queryctrl q = {.id = V4L2_CTRL_FLAG_NEXT_CTRL};
	while (xioctl(fd, VIDIOC_QUERYCTRL, &q) == 0) {
		if (!strcmp((char *)q.name, name)) {
			struct v4l2_control c = {.id = q.id, .value = value};
			if (xioctl(fd, VIDIOC_S_CTRL, &c) < 0)
				die("VIDIOC_S_CTRL");
			printf("control '%s' (0x%08x) = %d\n", name, q.id, value);
			return 0;
		}
		q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
	}
	fprintf(stderr, "capture_check: no control '%s'\n", name);
	exit(2);
}

static void gen_pattern(uint8_t *p, size_t n, unsigned frame)
{
	uint32_t x = 0x9e3779b9u * (frame + 1);
	for (size_t i = 0; i < n; i++) {
		x ^= x << 13;
		x ^= x >> 17;
		x ^= x << 5;
		p[i] = (uint8_t)x;
	}
}

static void load_frames(struct frames *f, const char *file, size_t size, unsigned gen_count)
{
	f->size = size;
	if (!file) {
		f->count = gen_count;
		f->data = malloc(size * gen_count);
		if (!f->data)
			die("malloc");
		for (unsigned i = 0; i < gen_count; i++)
			gen_pattern(f->data + i * size, size, i);
		return;
	}
	int fd = open(file, O_RDONLY);
	if (fd < 0)
		die(file);
	struct stat st;
	if (fstat(fd, &st) < 0)
		die("fstat");
	if (st.st_size == 0 || (size_t)st.st_size % size) {
		fprintf(stderr, "capture_check: %s has %lld bytes, not a multiple of the frame size %zu\n",
			file, (long long)st.st_size, size);
		exit(2);
	}
	f->count = (unsigned)((size_t)st.st_size / size);
	f->data = malloc((size_t)st.st_size);
	if (!f->data)
		die("malloc");
	size_t got = 0;
	while (got < (size_t)st.st_size) {
		ssize_t r = read(fd, f->data + got, (size_t)st.st_size - got);
		if (r <= 0)
			die("read");
		got += (size_t)r;
	}
	close(fd);
	printf("%u frames of %zu bytes from %s\n", f->count, size, file);
}

/* Prints which of f's frames buf equals (1), or how close the nearest is (0). */
static int match_frame(const uint8_t *a, size_t bytesused, const struct frames *f)
{
	size_t size = f->size, first_diff = 0, ndiff_best = size + 1;
	if (bytesused != size) {
		printf("  MISMATCH: bytesused %zu, frames of %zu bytes\n", bytesused, size);
		return 0;
	}
	for (unsigned j = 0; j < f->count; j++) {
		const uint8_t *e = f->data + (size_t)j * size;
		if (!memcmp(a, e, size)) {
			printf("  bytes match written frame %u\n", j);
			return 1;
		}
		size_t nd = 0, fd_ = 0;
		for (size_t i = 0; i < size; i++)
			if (a[i] != e[i]) {
				if (!nd)
					fd_ = i;
				nd++;
			}
		if (nd < ndiff_best) {
			ndiff_best = nd;
			first_diff = fd_;
		}
	}
	printf("  MISMATCH: the closest written frame differs in %zu of %zu bytes, first at byte %zu (got 0x%02x)\n",
	       ndiff_best, size, first_diff, a[first_diff]);
	return 0;
}

/* Sets up both ends of vivid's HDMI loop; returns with both formats set. */
static void setup_loop(struct stream *out, struct stream *cap, uint32_t fourcc, unsigned w,
		       unsigned h)
{
	select_hdmi(out->fd, 1);
	set_timings(out->fd, w, h, "output");
	select_hdmi(cap->fd, 0);
	set_timings(cap->fd, w, h, "capture");
	set_fmt(out, fourcc, w, h);
	set_fmt(cap, fourcc, w, h);
	if (out->fmt.fmt.pix.sizeimage != cap->fmt.fmt.pix.sizeimage ||
	    out->fmt.fmt.pix.bytesperline != cap->fmt.fmt.pix.bytesperline) {
		fprintf(stderr, "capture_check: output and capture layouts differ\n");
		exit(2);
	}
	/* vivid draws its on-screen text (counters, at 16,16) over looped frames too */
	set_ctrl_by_name(cap->fd, "OSD Text Mode", 2 /* None */);
	set_ctrl_by_name(cap->fd, "Loop Video", 1);
}

static void fill_out(struct stream *out, unsigned idx, const struct frames *f, unsigned k)
{
	memcpy(out->mem[idx], f->data + (size_t)(k % f->count) * f->size, f->size);
	qbuf(out, idx, f->size);
}

static int cmd_loop(const char *odev, const char *cdev, uint32_t fourcc, unsigned w, unsigned h,
		    unsigned n, const char *file)
{
	struct stream out = {.fd = open_dev(odev), .type = V4L2_BUF_TYPE_VIDEO_OUTPUT};
	struct stream cap = {.fd = open_dev(cdev), .type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
	setup_loop(&out, &cap, fourcc, w, h);
	size_t size = cap.fmt.fmt.pix.sizeimage;
	struct frames f;
	/* One frame by default: with a single known frame, whichever output buffer the capture
	 * copies from, the bytes must equal it. */
	load_frames(&f, file, size, 1);
	map_bufs(&out);
	map_bufs(&cap);
	unsigned written = 0;
	for (unsigned i = 0; i < out.n; i++)
		fill_out(&out, i, &f, written++);
	for (unsigned i = 0; i < cap.n; i++)
		qbuf(&cap, i, 0);
	double t0 = mono_now();
	streamon(&out);
	streamon(&cap);
	unsigned got = 0, match = 0;
	while (got < n) {
		struct pollfd p[2] = {{.fd = cap.fd, .events = POLLIN}, {.fd = out.fd, .events = POLLOUT}};
		int r = poll(p, 2, 10000);
		if (r < 0)
			die("poll");
		if (r == 0) {
			fprintf(stderr, "capture_check: no capture frame in 10 s\n");
			return 1;
		}
		struct v4l2_buffer b;
		if (p[1].revents & POLLOUT) {
			if (dqbuf(&out, &b, 0) == 0)
				fill_out(&out, b.index, &f, written++);
		}
		if (p[0].revents & POLLIN) {
			if (dqbuf(&cap, &b, 0) < 0)
				continue;
			print_buf(&b, t0);
			match += match_frame(cap.mem[b.index], b.bytesused, &f);
			got++;
			qbuf(&cap, b.index, 0);
		}
	}
	streamoff(&cap);
	streamoff(&out);
	char fs[5];
	fcc(fourcc, fs);
	printf("loop '%s' %ux%u: %u of %u captured frames equal a written frame (%u written): %s\n", fs,
	       w, h, match, got, written, match == got ? "EXACT" : "DIFFERENT");
	return match == got ? 0 : 1;
}

/* ---------------------------------------------------------------- feed */

static int cmd_feed(const char *odev, const char *cdev, uint32_t fourcc, unsigned w, unsigned h,
		    const char *file, double seconds)
{
	struct stream out = {.fd = open_dev(odev), .type = V4L2_BUF_TYPE_VIDEO_OUTPUT};
	struct stream cap = {.fd = open_dev(cdev), .type = V4L2_BUF_TYPE_VIDEO_CAPTURE};
	setup_loop(&out, &cap, fourcc, w, h);
	close(cap.fd); /* input, timings, format and the loop control stay set in vivid */
	struct frames f;
	load_frames(&f, file, out.fmt.fmt.pix.sizeimage, 1);
	map_bufs(&out);
	unsigned written = 0;
	for (unsigned i = 0; i < out.n; i++)
		fill_out(&out, i, &f, written++);
	streamon(&out);
	printf("feeding %s (capture from %s)\n", odev, cdev);
	fflush(stdout);
	double t0 = mono_now();
	while (seconds <= 0 || mono_now() - t0 < seconds) {
		struct v4l2_buffer b;
		if (dqbuf(&out, &b, 1000) == 0)
			fill_out(&out, b.index, &f, written++);
	}
	streamoff(&out);
	printf("fed %u frames\n", written);
	return 0;
}

static void usage(void)
{
	fprintf(stderr,
		"usage: capture_check list [DEV...]\n"
		"       capture_check capture DEV FOURCC W H [N] [FILE]\n"
		"       capture_check loop OUT CAP FOURCC W H [N] [FILE]\n"
		"       capture_check feed OUT CAP FOURCC W H FILE [SECONDS]\n");
	exit(2);
}

int main(int argc, char **argv)
{
	setvbuf(stdout, NULL, _IOLBF, 0);
	if (argc < 2)
		usage();
	const char *cmd = argv[1];
	if (!strcmp(cmd, "list"))
		return cmd_list(argc - 2, argv + 2);
	if (!strcmp(cmd, "capture") && argc >= 6)
		return cmd_capture(argv[2], parse_fcc(argv[3]), (unsigned)atoi(argv[4]),
				   (unsigned)atoi(argv[5]), argc > 6 ? (unsigned)atoi(argv[6]) : 5,
				   argc > 7 ? argv[7] : NULL);
	if (!strcmp(cmd, "loop") && argc >= 7)
		return cmd_loop(argv[2], argv[3], parse_fcc(argv[4]), (unsigned)atoi(argv[5]),
				(unsigned)atoi(argv[6]), argc > 7 ? (unsigned)atoi(argv[7]) : 5,
				argc > 8 ? argv[8] : NULL);
	if (!strcmp(cmd, "feed") && argc >= 8)
		return cmd_feed(argv[2], argv[3], parse_fcc(argv[4]), (unsigned)atoi(argv[5]),
				(unsigned)atoi(argv[6]), argv[7], argc > 8 ? atof(argv[8]) : 0);
	usage();
	return 2;
}
