// ps_camera_libcamera: libcamera behind a C port (see the header). The only
// C++ of the project, built as a shared module that ps_camera_libcamera_dl.c
// loads when a libcamera camera is used; every entry point catches what
// libcamera or the standard library may throw.
#include "ps_camera_libcamera.h"

#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <memory>
#include <mutex>
#include <new>
#include <string>
#include <vector>

#include <sys/mman.h>

#include <libcamera/libcamera.h>

namespace {

using namespace libcamera;

struct Mapping {
    uint8_t *base = nullptr;
    size_t length = 0;     // mapped bytes
    const uint8_t *data = nullptr;
    size_t plane_length = 0;
};

PixelFormat to_libcamera(ps_camera_format_t f)
{
    switch (f) {
    case PS_PIX_R8:
        return formats::R8;
    case PS_PIX_YUV420:
        return formats::YUV420;
    case PS_PIX_NV12:
        return formats::NV12;
    case PS_PIX_RGB888:
        return formats::RGB888;
    case PS_PIX_BGR888:
        return formats::BGR888;
    case PS_PIX_XRGB8888:
        return formats::XRGB8888;
    case PS_PIX_COUNT:
        break;
    }
    return PixelFormat();
}

void put_err(char *err, size_t err_len, const std::string &text)
{
    if (err != nullptr && err_len > 0)
        (void)std::snprintf(err, err_len, "camera: %s", text.c_str());
}

} // namespace

struct ps_camera_libcamera {
    ps_camera_cfg_t cfg{};
    std::unique_ptr<CameraManager> cm;
    std::shared_ptr<Camera> camera;
    bool is_acquired = false;
    bool is_streaming = false;
    std::unique_ptr<CameraConfiguration> config;
    Stream *stream = nullptr;
    unsigned int stride = 0;
    std::unique_ptr<FrameBufferAllocator> alloc;
    std::vector<Mapping> maps;
    std::vector<std::unique_ptr<Request>> requests;
    std::mutex mu; // completed requests, from libcamera's thread
    std::condition_variable cv;
    std::deque<Request *> done;
    std::atomic<unsigned long> n_bad{0};

    void on_complete(Request *r)
    {
        {
            std::lock_guard<std::mutex> lock(mu);
            done.push_back(r);
        }
        cv.notify_one();
    }

    int start(char *err, size_t err_len);
    int next(ps_camera_frame_t *out, int64_t timeout_ns);
    void release(const ps_camera_frame_t *f);
    void stop();
};

int ps_camera_libcamera::start(char *err, size_t err_len)
{
    stop();
    cm = std::make_unique<CameraManager>();
    int rc = cm->start();
    if (rc < 0) {
        put_err(err, err_len, std::string("the camera manager did not start: ") + strerror(-rc));
        cm.reset();
        return rc;
    }
    const std::string want = cfg.id;
    std::string known;
    for (const std::shared_ptr<Camera> &cam : cm->cameras()) {
        const std::string id = cam->id();
        const std::string model = cam->properties().get(properties::Model).value_or("");
        known += (known.empty() ? "" : ", ") + id + (model.empty() ? "" : " (" + model + ")");
        if (camera == nullptr && (want.empty() || id == want || id.find(want) != std::string::npos ||
                                  model.find(want) != std::string::npos))
            camera = cam;
    }
    if (camera == nullptr) {
        put_err(err, err_len,
                (want.empty() ? std::string("no camera found") : "no camera \"" + want + "\"") +
                    " (libcamera sees: " + (known.empty() ? "none" : known) + ")");
        stop();
        return -ENODEV;
    }
    if (camera->acquire() < 0) {
        put_err(err, err_len, camera->id() + " is in use by another process");
        stop();
        return -EBUSY;
    }
    is_acquired = true;
    config = camera->generateConfiguration({StreamRole::Viewfinder});
    if (config == nullptr || config->size() != 1) {
        put_err(err, err_len, camera->id() + " offers no viewfinder stream");
        stop();
        return -EINVAL;
    }
    StreamConfiguration &sc = config->at(0);
    const PixelFormat format = to_libcamera(cfg.format);
    sc.pixelFormat = format;
    sc.size = Size(cfg.width, cfg.height);
    sc.bufferCount = PS_CAMERA_LIBCAMERA_BUFFERS;
    const CameraConfiguration::Status st = config->validate();
    if (st == CameraConfiguration::Invalid || sc.pixelFormat != format ||
        sc.size != Size(cfg.width, cfg.height)) {
        put_err(err, err_len,
                camera->id() + " cannot stream " + std::to_string(cfg.width) + "x" +
                    std::to_string(cfg.height) + " " + ps_camera_format_name(cfg.format) +
                    "; it offers " + sc.toString() + " (set camera.width, height, format so)");
        stop();
        return -EINVAL;
    }
    rc = camera->configure(config.get());
    if (rc < 0) {
        put_err(err, err_len, "configuring " + camera->id() + " failed: " + strerror(-rc));
        stop();
        return -EIO;
    }
    stream = sc.stream();
    stride = sc.stride;
    alloc = std::make_unique<FrameBufferAllocator>(camera);
    rc = alloc->allocate(stream);
    if (rc <= 0) {
        put_err(err, err_len, "no buffers for " + camera->id());
        stop();
        return -ENOMEM;
    }
    const std::vector<std::unique_ptr<FrameBuffer>> &buffers = alloc->buffers(stream);
    for (size_t i = 0; i < buffers.size(); i++) {
        const FrameBuffer::Plane &plane = buffers[i]->planes()[0];
        Mapping m;
        m.length = static_cast<size_t>(plane.offset) + plane.length;
        void *p = mmap(nullptr, m.length, PROT_READ, MAP_SHARED, plane.fd.get(), 0);
        if (p == MAP_FAILED) {
            put_err(err, err_len, std::string("mapping a buffer failed: ") + strerror(errno));
            stop();
            return -EIO;
        }
        m.base = static_cast<uint8_t *>(p);
        m.data = m.base + plane.offset;
        m.plane_length = plane.length;
        maps.push_back(m);
        std::unique_ptr<Request> r = camera->createRequest(i);
        if (r == nullptr || r->addBuffer(stream, buffers[i].get()) < 0) {
            put_err(err, err_len, "no request for " + camera->id());
            stop();
            return -ENOMEM;
        }
        requests.push_back(std::move(r));
    }
    camera->requestCompleted.connect(this, &ps_camera_libcamera::on_complete);
    ControlList controls(controls::controls);
    if (cfg.fps > 0 && camera->controls().count(&controls::FrameDurationLimits) > 0) {
        const int64_t frame_us = static_cast<int64_t>(1e6 / cfg.fps);
        controls.set(controls::FrameDurationLimits, {frame_us, frame_us});
    }
    rc = camera->start(&controls);
    if (rc < 0) {
        put_err(err, err_len, "starting " + camera->id() + " failed: " + strerror(-rc));
        stop();
        return -EIO;
    }
    is_streaming = true;
    for (std::unique_ptr<Request> &r : requests) {
        if (camera->queueRequest(r.get()) < 0) {
            put_err(err, err_len, "queueing a request on " + camera->id() + " failed");
            stop();
            return -EIO;
        }
    }
    return 0;
}

int ps_camera_libcamera::next(ps_camera_frame_t *out, int64_t timeout_ns)
{
    if (!is_streaming)
        return -EIO;
    Request *r = nullptr;
    {
        std::unique_lock<std::mutex> lock(mu);
        if (!cv.wait_for(lock, std::chrono::nanoseconds(timeout_ns), [this] { return !done.empty(); }))
            return -ETIMEDOUT;
        r = done.front();
        done.pop_front();
    }
    const size_t idx = static_cast<size_t>(r->cookie());
    FrameBuffer *fb = r->buffers().begin()->second;
    const FrameMetadata &md = fb->metadata();
    if (r->status() != Request::RequestComplete || md.status != FrameMetadata::FrameSuccess ||
        idx >= maps.size()) {
        n_bad++;
        if (r->status() != Request::RequestCancelled && idx < requests.size()) {
            r->reuse(Request::ReuseBuffers);
            (void)camera->queueRequest(r); /* a failure shows as frames that stop coming */
        }
        return -EIO;
    }
    const std::optional<int64_t> sensor_ts = r->metadata().get(controls::SensorTimestamp);
    const int64_t t = sensor_ts.has_value() ? *sensor_ts : static_cast<int64_t>(md.timestamp);
    const size_t used = md.planes().empty() ? 0u : md.planes()[0].bytesused;
    *out = ps_camera_frame_t{};
    out->data = maps[idx].data;
    out->n_bytes = used > 0 && used <= maps[idx].plane_length ? used : maps[idx].plane_length;
    out->width = cfg.width;
    out->height = cfg.height;
    out->stride = stride;
    out->format = cfg.format;
    out->t_ns = t;
    out->t_mono_ns = t;
    out->seq = md.sequence;
    out->buf_idx = static_cast<uint32_t>(idx);
    return 0;
}

void ps_camera_libcamera::release(const ps_camera_frame_t *f)
{
    if (!is_streaming || f->buf_idx >= requests.size())
        return;
    Request *r = requests[f->buf_idx].get();
    r->reuse(Request::ReuseBuffers);
    if (camera->queueRequest(r) < 0)
        n_bad++;
}

void ps_camera_libcamera::stop()
{
    if (is_streaming) {
        (void)camera->stop(); /* completes every queued request as cancelled */
        is_streaming = false;
    }
    if (camera != nullptr)
        camera->requestCompleted.disconnect(this);
    {
        std::lock_guard<std::mutex> lock(mu);
        done.clear();
    }
    requests.clear();
    for (const Mapping &m : maps)
        (void)munmap(m.base, m.length);
    maps.clear();
    if (alloc != nullptr && stream != nullptr)
        (void)alloc->free(stream);
    alloc.reset();
    stream = nullptr;
    config.reset();
    if (is_acquired)
        (void)camera->release();
    is_acquired = false;
    camera.reset();
    if (cm != nullptr)
        cm->stop();
    cm.reset();
}

namespace {

int port_start(void *ctx, char *err, size_t err_len)
{
    try {
        return static_cast<ps_camera_libcamera *>(ctx)->start(err, err_len);
    } catch (const std::bad_alloc &) {
        put_err(err, err_len, "out of memory");
        return -ENOMEM;
    } catch (...) {
        put_err(err, err_len, "libcamera failed");
        return -EIO;
    }
}

int port_next(void *ctx, ps_camera_frame_t *out, int64_t timeout_ns)
{
    try {
        return static_cast<ps_camera_libcamera *>(ctx)->next(out, timeout_ns);
    } catch (...) {
        return -EIO;
    }
}

void port_release(void *ctx, const ps_camera_frame_t *f)
{
    try {
        static_cast<ps_camera_libcamera *>(ctx)->release(f);
    } catch (...) {
        /* the buffer is lost to the stream; frames keep coming on the others */
    }
}

void port_stop(void *ctx)
{
    try {
        static_cast<ps_camera_libcamera *>(ctx)->stop();
    } catch (...) {
        /* stopping is best effort: the process ends or starts over */
    }
}

const ps_camera_ops_t LIBCAMERA_OPS = {port_start, port_next, port_release, port_stop};

} // namespace

extern "C" int ps_camera_libcamera_impl_create(const ps_camera_cfg_t *cfg,
                                               ps_camera_libcamera_t **out)
{
    if (cfg == nullptr || out == nullptr || cfg->source != PS_CAMERA_SRC_LIBCAMERA ||
        !to_libcamera(cfg->format).isValid())
        return -EINVAL;
    /* libcamera logs INFO and WARN lines to stderr from its own threads;
     * unless the user asked for a level, only its errors. */
    (void)setenv("LIBCAMERA_LOG_LEVELS", "*:ERROR", 0);
    ps_camera_libcamera *c = new (std::nothrow) ps_camera_libcamera();
    if (c == nullptr)
        return -ENOMEM;
    c->cfg = *cfg;
    *out = c;
    return 0;
}

extern "C" ps_camera_port_t ps_camera_libcamera_impl_port(ps_camera_libcamera_t *c)
{
    return ps_camera_port_t{&LIBCAMERA_OPS, c};
}

extern "C" unsigned long ps_camera_libcamera_impl_n_bad_frames(const ps_camera_libcamera_t *c)
{
    return c->n_bad.load(std::memory_order_relaxed);
}

extern "C" void ps_camera_libcamera_impl_destroy(ps_camera_libcamera_t *c)
{
    if (c == nullptr)
        return;
    port_stop(c);
    delete c;
}
