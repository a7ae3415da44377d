#include "ps_can_socket.h"

/* net/if.h before the kernel's headers: their libc-compat then skips
 * linux/if.h's duplicates of it. */
#include <net/if.h>

#include <errno.h>
#include <fcntl.h>
#include <libmnl/libmnl.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/netlink.h>
#include <linux/can/raw.h>
#include <linux/if_arp.h>
#include <linux/if_link.h>
#include <linux/rtnetlink.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "../rt/ps_err.h"

_Static_assert(sizeof(((ps_can_socket_slot_t *)0)->frame) >= sizeof(struct canfd_frame),
               "slot holds an FD frame");

static int64_t now_ns(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

/* ---- error frames ------------------------------------------------------ */

/* Leaving bus-off: a controller that reports a state again (passive,
 * warning, back to active: drivers with automatic recovery) or "restarted",
 * or that hands over a data frame (a bus-off controller receives nothing),
 * is on the bus again. Without these a lost RESTARTED frame, or an
 * `ip link set down/up`, would leave the bus off for good. */
static void leave_bus_off(ps_can_state_t *st)
{
    if (st->mode == PS_CAN_BUS_OFF)
        st->n_restarts++;
    st->mode = PS_CAN_BUS_ERROR_ACTIVE;
}

static void apply_ctrl_error(ps_can_state_t *st, uint8_t ctrl)
{
    if (ctrl & (CAN_ERR_CRTL_RX_OVERFLOW | CAN_ERR_CRTL_TX_OVERFLOW))
        st->n_ctrl_overflow++;
    if (ctrl & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE | CAN_ERR_CRTL_RX_WARNING |
                CAN_ERR_CRTL_TX_WARNING | CAN_ERR_CRTL_ACTIVE))
        leave_bus_off(st);
    if (ctrl & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE))
        st->mode = PS_CAN_BUS_ERROR_PASSIVE;
    else if (ctrl & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING))
        st->mode = PS_CAN_BUS_ERROR_WARNING;
    else if (ctrl & CAN_ERR_CRTL_ACTIVE)
        st->mode = PS_CAN_BUS_ERROR_ACTIVE;
}

void ps_can_socket_apply_error(ps_can_state_t *st, uint32_t can_id, const uint8_t data[8])
{
    st->n_err_frames++;
    if (can_id & CAN_ERR_CRTL)
        apply_ctrl_error(st, data[1]);
    if (can_id & (CAN_ERR_PROT | CAN_ERR_BUSERROR))
        st->n_prot_errors++;
    if (can_id & CAN_ERR_ACK)
        st->n_no_ack++;
    if (can_id & CAN_ERR_RESTARTED) {
        if (st->mode != PS_CAN_BUS_OFF)
            st->n_restarts++; /* leave_bus_off counts it otherwise */
        leave_bus_off(st);
    }
    if (can_id & CAN_ERR_BUSOFF) {
        if (st->mode != PS_CAN_BUS_OFF)
            st->n_bus_off++;
        st->mode = PS_CAN_BUS_OFF;
    }
    if (can_id & CAN_ERR_CNT) {
        st->tx_error_count = data[6];
        st->rx_error_count = data[7];
    }
}

/* ---- open / close ------------------------------------------------------ */

static int fail(ps_can_socket_t *s, char *err, size_t len, const char *what, int e)
{
    ps_err_format(err, len, "CAN %s: %s: %s", s->ifname, what, strerror(e));
    ps_can_socket_close(s);
    return -e;
}

static int set_opt(int fd, int level, int name, const void *v, socklen_t n)
{
    return setsockopt(fd, level, name, v, n) < 0 ? -errno : 0;
}

static int set_filters(ps_can_socket_t *s, const ps_can_socket_cfg_t *cfg)
{
    struct can_filter f[PS_CAN_SOCKET_MAX_FILTERS];
    for (uint32_t i = 0; i < cfg->n_filters; i++) {
        const ps_can_socket_filter_t *in = &cfg->filters[i];
        /* The EFF bit in both id and mask: an 11-bit filter never passes a
         * 29-bit frame whose low bits happen to match, and the reverse. RTR
         * in the mask with RTR clear in the id: remote frames never pass. */
        f[i].can_id = (in->id & (in->is_ext ? CAN_EFF_MASK : CAN_SFF_MASK)) |
                      (in->is_ext ? CAN_EFF_FLAG : 0u);
        f[i].can_mask =
            (in->mask & (in->is_ext ? CAN_EFF_MASK : CAN_SFF_MASK)) | CAN_EFF_FLAG | CAN_RTR_FLAG;
    }
    /* n 0: an empty filter list, nothing but error frames arrives. */
    return set_opt(s->fd, SOL_CAN_RAW, CAN_RAW_FILTER, f,
                   (socklen_t)(cfg->n_filters * sizeof(f[0])));
}

static int configure(ps_can_socket_t *s, const ps_can_socket_cfg_t *cfg, const char **what)
{
    const int on = 1;
    const can_err_mask_t err_mask = CAN_ERR_MASK;
    int rc;
    *what = "CAN_RAW_FILTER";
    if ((rc = set_filters(s, cfg)) < 0)
        return rc;
    *what = "CAN_RAW_ERR_FILTER";
    if ((rc = set_opt(s->fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof(err_mask))) < 0)
        return rc;
    *what = "CAN_RAW_FD_FRAMES";
    if (cfg->is_fd && (rc = set_opt(s->fd, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof(on))) < 0)
        return rc;
    *what = "SO_TIMESTAMPNS";
    if ((rc = set_opt(s->fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on))) < 0)
        return rc;
    *what = "SO_RXQ_OVFL";
    return set_opt(s->fd, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof(on));
}

int ps_can_socket_open(ps_can_socket_t *s, const ps_can_socket_cfg_t *cfg, char *err,
                       size_t err_len)
{
    memset(s, 0, sizeof(*s));
    s->fd = -1;
    snprintf(s->ifname, sizeof(s->ifname), "%s", cfg->ifname);
    if (cfg->ifname[0] == '\0' || strlen(cfg->ifname) >= IFNAMSIZ ||
        cfg->n_filters > PS_CAN_SOCKET_MAX_FILTERS) {
        ps_err_format(err, err_len, "CAN '%s': bad interface name or more than %u filters",
                      cfg->ifname, PS_CAN_SOCKET_MAX_FILTERS);
        return -EINVAL;
    }
    s->is_fd = cfg->is_fd;
    s->bitrate = cfg->bitrate;
    s->ifindex = (int)if_nametoindex(cfg->ifname);
    if (s->ifindex == 0)
        return fail(s, err, err_len, "no such interface (ip link show)", ENODEV);
    s->fd = socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
    if (s->fd < 0)
        return fail(s, err, err_len, "socket(PF_CAN)", errno);
    s->is_open = true;
    const char *what = "";
    int rc = configure(s, cfg, &what);
    if (rc < 0)
        return fail(s, err, err_len, what, -rc);
    struct sockaddr_can addr = {.can_family = AF_CAN, .can_ifindex = s->ifindex};
    if (bind(s->fd, (struct sockaddr *)&addr, sizeof(addr)) < 0)
        return fail(s, err, err_len, "bind", errno);
    s->open_ns = now_ns(CLOCK_MONOTONIC);
    return 0;
}

void ps_can_socket_close(ps_can_socket_t *s)
{
    if (s->is_open && s->fd >= 0)
        close(s->fd); /* is_open: a zeroed struct's fd 0 is not ours */
    s->fd = -1;
    s->is_open = false;
}

/* ---- frames ------------------------------------------------------------ */

/* Bits a frame took on the wire, for the load figure: the unstuffed length
 * (the planner's lower bound); FD data bytes at the nominal rate's cost. */
static unsigned wire_bits(const ps_can_frame_t *f)
{
    const uint8_t len = f->len <= PS_CAN_MAX_DLEN ? f->len : PS_CAN_MAX_DLEN;
    unsigned bits = ps_canbus_frame_bits_min(len, f->is_ext != 0);
    if (f->len > PS_CAN_MAX_DLEN)
        bits += 8u * (f->len - PS_CAN_MAX_DLEN);
    return bits;
}

static void to_kernel(const ps_can_frame_t *in, struct canfd_frame *out)
{
    memset(out, 0, sizeof(*out));
    out->can_id = in->is_ext ? ((in->id & CAN_EFF_MASK) | CAN_EFF_FLAG) : (in->id & CAN_SFF_MASK);
    out->len = in->len;
    if (in->is_fd && in->is_brs)
        out->flags = CANFD_BRS;
    memcpy(out->data, in->data, in->len);
}

static int socket_send_batch(void *ctx, const ps_can_frame_t *frames, size_t n)
{
    ps_can_socket_t *s = ctx;
    struct mmsghdr msgs[PS_CAN_SOCKET_BATCH];
    struct iovec iov[PS_CAN_SOCKET_BATCH];
    size_t k = 0;
    for (; k < n && k < PS_CAN_SOCKET_BATCH; k++) {
        const ps_can_frame_t *f = &frames[k];
        if (!ps_can_is_valid_frame(f) || (f->is_fd && !s->is_fd))
            return -EINVAL; /* the caller's bug: nothing sent */
        to_kernel(f, (struct canfd_frame *)s->tx[k].frame);
        iov[k] = (struct iovec){s->tx[k].frame, f->is_fd ? CANFD_MTU : CAN_MTU};
        msgs[k] = (struct mmsghdr){.msg_hdr = {.msg_iov = &iov[k], .msg_iovlen = 1}};
    }
    int sent = k > 0 ? sendmmsg(s->fd, msgs, (unsigned)k, MSG_DONTWAIT) : 0;
    if (sent < 0) {
        if (errno != ENOBUFS && errno != EAGAIN)
            return -errno;
        sent = 0;
    }
    if ((size_t)sent < n) {
        s->state.n_tx_saturated++;
        s->state.n_tx_dropped += n - (size_t)sent;
    }
    for (int i = 0; i < sent; i++)
        s->state.n_bits += wire_bits(&frames[i]);
    s->state.n_tx_frames += (uint64_t)sent;
    return sent;
}

static void take_control(ps_can_socket_t *s, struct msghdr *h, int64_t offset_ns, int64_t mono_now,
                         int64_t *out_t_ns)
{
    *out_t_ns = mono_now;
    for (struct cmsghdr *c = CMSG_FIRSTHDR(h); c != NULL; c = CMSG_NXTHDR(h, c)) {
        if (c->cmsg_level != SOL_SOCKET)
            continue;
        if (c->cmsg_type == SCM_TIMESTAMPNS) {
            struct timespec ts;
            memcpy(&ts, CMSG_DATA(c), sizeof(ts));
            const int64_t t = (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec + offset_ns;
            *out_t_ns = t < mono_now ? t : mono_now;
        } else if (c->cmsg_type == SO_RXQ_OVFL) {
            uint32_t dropped; /* since the socket was made, by open */
            memcpy(&dropped, CMSG_DATA(c), sizeof(dropped));
            s->state.n_rx_dropped = dropped;
        }
    }
}

/* @return 1 a data frame in *out, 0 consumed (error or remote frame) */
static int from_kernel(ps_can_socket_t *s, const struct canfd_frame *k, size_t size,
                       ps_can_frame_t *out)
{
    if (k->can_id & CAN_ERR_FLAG) {
        ps_can_socket_apply_error(&s->state, k->can_id, k->data);
        return 0;
    }
    if ((k->can_id & CAN_RTR_FLAG) || (size != CAN_MTU && size != CANFD_MTU))
        return 0;
    if (s->state.mode == PS_CAN_BUS_OFF)
        leave_bus_off(&s->state);
    const bool is_fd = size == CANFD_MTU;
    out->is_ext = (k->can_id & CAN_EFF_FLAG) != 0;
    out->id = k->can_id & (out->is_ext ? CAN_EFF_MASK : CAN_SFF_MASK);
    out->is_fd = is_fd;
    out->is_brs = is_fd && (k->flags & CANFD_BRS) != 0;
    out->len = k->len <= (is_fd ? CANFD_MAX_DLEN : CAN_MAX_DLEN) ? k->len : 0;
    memcpy(out->data, k->data, out->len);
    return 1;
}

static int socket_recv_batch(void *ctx, ps_can_frame_t *out, size_t max)
{
    ps_can_socket_t *s = ctx;
    struct mmsghdr msgs[PS_CAN_SOCKET_BATCH];
    struct iovec iov[PS_CAN_SOCKET_BATCH];
    const size_t want = max < PS_CAN_SOCKET_BATCH ? max : PS_CAN_SOCKET_BATCH;
    for (size_t i = 0; i < want; i++) {
        iov[i] = (struct iovec){s->rx[i].frame, sizeof(struct canfd_frame)};
        msgs[i] = (struct mmsghdr){.msg_hdr = {.msg_iov = &iov[i],
                                               .msg_iovlen = 1,
                                               .msg_control = s->rx[i].control,
                                               .msg_controllen = sizeof(s->rx[i].control)}};
    }
    int got = want > 0 ? recvmmsg(s->fd, msgs, (unsigned)want, MSG_DONTWAIT, NULL) : 0;
    if (got < 0)
        return (errno == EAGAIN || errno == EWOULDBLOCK) ? 0 : -errno;
    const int64_t mono = now_ns(CLOCK_MONOTONIC);
    const int64_t offset = mono - now_ns(CLOCK_REALTIME);
    int n = 0;
    for (int i = 0; i < got; i++) {
        if (from_kernel(s, (const struct canfd_frame *)s->rx[i].frame, msgs[i].msg_len, &out[n]) ==
            0) {
            take_control(s, &msgs[i].msg_hdr, offset, mono, &out[n].t_ns);
            continue;
        }
        take_control(s, &msgs[i].msg_hdr, offset, mono, &out[n].t_ns);
        s->state.n_bits += wire_bits(&out[n]);
        n++;
    }
    s->state.n_rx_frames += (uint64_t)n;
    return n;
}

static int socket_get_state(void *ctx, ps_can_state_t *out)
{
    ps_can_socket_t *s = ctx;
    if (s->fd < 0)
        return -EBADF;
    *out = s->state;
    /* A bus-off that began and ended within one receive batch (the error
     * frame, then data frames) is still reported once: the loop reads the
     * state once a tick and must see every episode. */
    if (s->state.n_bus_off != s->n_bus_off_reported)
        out->mode = PS_CAN_BUS_OFF;
    s->n_bus_off_reported = s->state.n_bus_off;
    const int64_t elapsed_ns = now_ns(CLOCK_MONOTONIC) - s->open_ns;
    out->load = (s->bitrate > 0 && elapsed_ns > 0)
                    ? (double)s->state.n_bits / ((double)s->bitrate * (double)elapsed_ns * 1e-9)
                    : 0.0;
    return 0;
}

static void socket_close(void *ctx)
{
    ps_can_socket_close(ctx);
}

static const ps_can_ops_t SOCKET_OPS = {
    .send_batch = socket_send_batch,
    .recv_batch = socket_recv_batch,
    .get_state = socket_get_state,
    .close = socket_close,
};

ps_can_port_t ps_can_socket_port(ps_can_socket_t *s)
{
    return (ps_can_port_t){.ops = &SOCKET_OPS, .ctx = s, .name = s->ifname};
}

/* ---- rtnetlink query --------------------------------------------------- */

static int parse_can_data(const struct nlattr *a, void *data)
{
    ps_can_socket_iface_t *o = data;
    switch (mnl_attr_get_type(a)) {
    case IFLA_CAN_BITTIMING:
        if (mnl_attr_get_payload_len(a) >= sizeof(struct can_bittiming)) {
            struct can_bittiming bt;
            memcpy(&bt, mnl_attr_get_payload(a), sizeof(bt));
            o->bitrate = bt.bitrate;
            o->has_bittiming = true;
        }
        break;
    case IFLA_CAN_DATA_BITTIMING:
        if (mnl_attr_get_payload_len(a) >= sizeof(struct can_bittiming)) {
            struct can_bittiming bt;
            memcpy(&bt, mnl_attr_get_payload(a), sizeof(bt));
            o->data_bitrate = bt.bitrate;
        }
        break;
    case IFLA_CAN_CTRLMODE:
        if (mnl_attr_get_payload_len(a) >= sizeof(struct can_ctrlmode)) {
            struct can_ctrlmode cm;
            memcpy(&cm, mnl_attr_get_payload(a), sizeof(cm));
            o->is_fd_mode = (cm.flags & CAN_CTRLMODE_FD) != 0;
        }
        break;
    case IFLA_CAN_STATE:
        if (mnl_attr_validate(a, MNL_TYPE_U32) == 0)
            o->can_state = (int)mnl_attr_get_u32(a);
        break;
    case IFLA_CAN_RESTART_MS:
        if (mnl_attr_validate(a, MNL_TYPE_U32) == 0)
            o->restart_ms = mnl_attr_get_u32(a);
        break;
    default:
        break;
    }
    return MNL_CB_OK;
}

static int parse_linkinfo(const struct nlattr *a, void *data)
{
    ps_can_socket_iface_t *o = data;
    if (mnl_attr_get_type(a) == IFLA_INFO_KIND && mnl_attr_validate(a, MNL_TYPE_STRING) == 0)
        snprintf(o->kind, sizeof(o->kind), "%s", mnl_attr_get_str(a));
    else if (mnl_attr_get_type(a) == IFLA_INFO_DATA)
        mnl_attr_parse_nested(a, parse_can_data, o);
    return MNL_CB_OK;
}

static int parse_link_attr(const struct nlattr *a, void *data)
{
    ps_can_socket_iface_t *o = data;
    switch (mnl_attr_get_type(a)) {
    case IFLA_MTU:
        if (mnl_attr_validate(a, MNL_TYPE_U32) == 0)
            o->mtu = mnl_attr_get_u32(a);
        break;
    case IFLA_TXQLEN:
        if (mnl_attr_validate(a, MNL_TYPE_U32) == 0)
            o->txqueuelen = mnl_attr_get_u32(a);
        break;
    case IFLA_LINKINFO:
        mnl_attr_parse_nested(a, parse_linkinfo, o);
        break;
    default:
        break;
    }
    return MNL_CB_OK;
}

static int parse_link(const struct nlmsghdr *nlh, void *data)
{
    ps_can_socket_iface_t *o = data;
    const struct ifinfomsg *ifm = mnl_nlmsg_get_payload(nlh);
    o->exists = true;
    o->is_can = ifm->ifi_type == ARPHRD_CAN;
    o->is_up = (ifm->ifi_flags & IFF_UP) != 0;
    return mnl_attr_parse(nlh, sizeof(*ifm), parse_link_attr, o);
}

int ps_can_socket_query(const char *ifname, ps_can_socket_iface_t *out, char *err, size_t err_len)
{
    memset(out, 0, sizeof(*out));
    out->can_state = -1;
    if (strlen(ifname) >= IFNAMSIZ) {
        ps_err_format(err, err_len, "CAN '%s': interface name too long", ifname);
        return -EINVAL;
    }
    char buf[8192];
    struct nlmsghdr *nlh = mnl_nlmsg_put_header(buf);
    nlh->nlmsg_type = RTM_GETLINK;
    nlh->nlmsg_flags = NLM_F_REQUEST;
    nlh->nlmsg_seq = 1;
    struct ifinfomsg *ifm = mnl_nlmsg_put_extra_header(nlh, sizeof(*ifm));
    ifm->ifi_family = AF_UNSPEC;
    mnl_attr_put_strz(nlh, IFLA_IFNAME, ifname);
    struct mnl_socket *nl = mnl_socket_open(NETLINK_ROUTE);
    if (nl == NULL || mnl_socket_bind(nl, 0, MNL_SOCKET_AUTOPID) < 0 ||
        mnl_socket_sendto(nl, nlh, nlh->nlmsg_len) < 0) {
        const int e = errno;
        ps_err_format(err, err_len, "CAN %s: rtnetlink request: %s", ifname, strerror(e));
        if (nl != NULL)
            mnl_socket_close(nl);
        return -e;
    }
    const unsigned portid = mnl_socket_get_portid(nl);
    ssize_t n = mnl_socket_recvfrom(nl, buf, sizeof(buf));
    int rc = n < 0 ? -errno : mnl_cb_run(buf, (size_t)n, 1, portid, parse_link, out);
    const int e = errno;
    mnl_socket_close(nl);
    if (rc < 0 && e == ENODEV) {
        out->exists = false; /* the kernel's answer to a name it does not know */
        return 0;
    }
    if (rc < 0) {
        ps_err_format(err, err_len, "CAN %s: rtnetlink answer: %s", ifname, strerror(e));
        return -e;
    }
    return 0;
}

/* ---- the start-up check ------------------------------------------------ */

typedef struct {
    char *buf;
    size_t len, used;
} text_t;

__attribute__((format(printf, 2, 3))) static void add(text_t *t, const char *fmt, ...)
{
    if (t->buf == NULL || t->len == 0 || t->used >= t->len - 1)
        return;
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(t->buf + t->used, t->len - t->used, fmt, ap);
    va_end(ap);
    if (n > 0)
        t->used += (size_t)n < t->len - t->used ? (size_t)n : t->len - t->used - 1;
}

static void bring_up_cmd(text_t *t, const ps_canbus_bus_cfg_t *bus)
{
    add(t, "sudo ip link set %s down; sudo ip link set %s type can bitrate %u", bus->ifname,
        bus->ifname, bus->bitrate);
    if (bus->is_fd)
        add(t, " dbitrate %u fd on", bus->data_bitrate);
    add(t, " restart-ms 100; sudo ip link set %s up", bus->ifname);
}

static void check_timing(text_t *e, const ps_canbus_bus_cfg_t *bus, const ps_can_socket_iface_t *i)
{
    const bool fd_wrong = bus->is_fd && (!i->is_fd_mode || i->data_bitrate != bus->data_bitrate);
    if (i->bitrate != bus->bitrate || fd_wrong || (!bus->is_fd && i->is_fd_mode)) {
        add(e, "; %s runs %u bit/s%s", bus->ifname, i->bitrate, i->is_fd_mode ? " FD" : "");
        if (i->is_fd_mode)
            add(e, " data %u bit/s", i->data_bitrate);
        add(e, ", the board wants %u%s: ", bus->bitrate, bus->is_fd ? " FD" : " classical");
        bring_up_cmd(e, bus);
    }
    if (i->can_state == CAN_STATE_BUS_OFF || i->can_state == CAN_STATE_STOPPED)
        add(e,
            "; %s is %s: check wiring and termination, then `sudo ip link set %s type can "
            "restart`",
            bus->ifname, i->can_state == CAN_STATE_BUS_OFF ? "bus-off" : "stopped", bus->ifname);
    if (i->restart_ms == 0)
        add(e,
            "; %s has restart-ms 0 (stays bus-off for ever): `sudo ip link set %s down; sudo "
            "ip link set %s type can restart-ms 100; sudo ip link set %s up`",
            bus->ifname, bus->ifname, bus->ifname, bus->ifname);
}

int ps_can_socket_check_iface(const ps_canbus_bus_cfg_t *bus, const ps_can_socket_iface_t *info,
                              uint32_t min_txqueuelen, char *err, size_t err_len, char *note,
                              size_t note_len)
{
    text_t e = {err, err_len, 0}, n = {note, note_len, 0};
    if (err_len > 0)
        err[0] = '\0';
    if (note_len > 0)
        note[0] = '\0';
    if (!info->exists) {
        add(&e,
            "; no interface %s (`ip link show`): on a board check the CAN overlay or driver; "
            "for a test: `sudo ip link add %s type vcan`",
            bus->ifname, bus->ifname);
    } else if (!info->is_can) {
        add(&e, "; %s is not a CAN interface (`ip -details link show %s`)", bus->ifname,
            bus->ifname);
    } else {
        const bool is_real = strcmp(info->kind, "can") == 0 || info->has_bittiming;
        if (is_real)
            check_timing(&e, bus, info);
        else
            add(&n, "%s: virtual (%s), bitrate not checked", bus->ifname,
                info->kind[0] ? info->kind : "unknown kind");
        if (bus->is_fd && info->mtu < CANFD_MTU) /* larger: CAN XL, carries FD too */
            add(&e, "; %s has mtu %u, CAN FD needs %u: `sudo ip link set %s mtu %u`", bus->ifname,
                info->mtu, (unsigned)CANFD_MTU, bus->ifname, (unsigned)CANFD_MTU);
        if (!info->is_up) {
            add(&e, "; %s is down: ", bus->ifname);
            if (is_real)
                bring_up_cmd(&e, bus);
            else
                add(&e, "`sudo ip link set %s up`", bus->ifname);
        }
        if (info->txqueuelen < min_txqueuelen)
            add(&e,
                "; %s has txqueuelen %u, the loop needs at least %u: `sudo ip link set %s "
                "txqueuelen %u`",
                bus->ifname, info->txqueuelen, min_txqueuelen, bus->ifname, min_txqueuelen);
    }
    if (e.used == 0)
        return 0;
    if (e.used >= 2) /* drop the leading "; " */
        memmove(err, err + 2, e.used - 1);
    return -PS_ERR_CONFIG;
}
