# pushstep: real-time balance controller runtime.  `make help` lists targets.
.DEFAULT_GOAL := all
SHELL := /bin/bash

# ARCH=aarch64 (or arm64): cross-build with Debian's aarch64 toolchain and the
# arm64 -dev packages (multiarch) into build-aarch64/; `make test ARCH=aarch64`
# runs the unit tests under qemu-user (tools/test-aarch64.sh). Any other ARCH,
# or none: a native build.
ARCH    ?=
ifneq ($(filter aarch64 arm64,$(ARCH)),)
IS_CROSS := 1
BUILD   ?= build-aarch64
CC      := aarch64-linux-gnu-gcc
CXX     := aarch64-linux-gnu-g++
DEB_ARCH := arm64
endif
BUILD   ?= build
ARGS    ?=
CC      ?= cc
CXX     ?= c++

# Debian 12 packages (README says why each is there). BUILD_PKGS build, test
# and run the system; TOOL_PKGS are for working with targets (cyclictest,
# can-utils). `make deps` installs both.
BUILD_PKGS := gcc libc6-dev make pkg-config libmujoco-dev libcyaml-dev libyaml-dev \
              libcmocka-dev libcjson-dev libmnl-dev libgpiod-dev \
              libzstd-dev liblz4-dev zlib1g-dev
# Camera perception: libcamera (C++: g++), AprilTag detection; PNG images in
# and out, offscreen OpenGL through EGL on Mesa's software rasteriser for the
# simulated camera and the crowd's pictures (--render, sim/ps_render.h), a
# GLFW window (--view), ffmpeg for the crowd's MP4.
BUILD_PKGS += g++ libcamera-dev libapriltag-dev libpng-dev libegl-dev libegl-mesa0 \
              libgl1-mesa-dri libglfw3-dev ffmpeg
TOOL_PKGS  := rt-tests can-utils
# What `make test` needs beyond building: can-utils' log2long reads the
# candump-format lines the runtime writes (tests/test_candump.c); systemd's
# systemd-analyze reads the shipped unit (tools/test-install.sh); gnuplot
# draws `pushstep log --plot` (tests/test_e2e_recorder.c); libcamera's vimc
# IPA module and udevd for the VM's emulated camera (test_hw_camera); the
# policy tools' tests (policy/train/test_tools.py, tests/test_train_smoke.sh)
# run the ONNX importer and a short training; and the aarch64 cross tools
# (AARCH64_PKGS below) for the aarch64 part of the suite.
TEST_PKGS  := can-utils systemd gnuplot-nox libcamera-ipa udev \
              python3 python3-numpy python3-onnx python3-hypothesis python3-torch \
              python3-yaml python3-tqdm libblas3 liblapack3
# The fuzz targets (tests/fuzz/, docs/fuzzing.md): clang with libFuzzer and
# its sanitizer runtimes (libclang-rt-14-dev is only a recommendation of
# clang-14's, so it is named).
TEST_PKGS  += clang-14 libclang-rt-14-dev
# Extra packages `make bench` needs: load generator, plots, the analysis script,
# GNU parallel for the push-recovery grid (bench/push.py), OpenBLAS and
# libtorch for the inference comparison (bench/policy.sh).
BENCH_PKGS := stress-ng gnuplot-nox python3 parallel libopenblas-dev libtorch-dev
# What `make train` needs (policy/train/, never at run time). libblas3,
# liblapack3: the reference BLAS and LAPACK that train.py pins
# (policy/train/portable.py); OpenBLAS would otherwise stand in for them and
# round by the CPU it finds.
TRAIN_PKGS := python3 python3-torch python3-numpy python3-yaml python3-tqdm gnuplot-nox libblas3 liblapack3
# ARCH=aarch64: the cross compiler, qemu-user to run its tests, and the arm64
# builds of the libraries the binaries link (multiarch; tools/deps.sh adds
# the arm64 architecture to dpkg when a package names it).
# libapriltag-dev's amd64 and arm64 builds cannot be installed together
# (each ships its own /usr/share/apriltag/cmake/apriltagTargets-none.cmake),
# so the cross build takes the headers from the native -dev package and
# links the arm64 runtime library, libapriltag3, by its soname (every build
# links it so: the same command line for both). libegl-mesa0 and
# libgl1-mesa-dri: Mesa's EGL and software rasteriser, which the simulated
# camera's tests render with under qemu-user (tools/test-aarch64.sh).
CROSS_LIBS := libc6-dev libmujoco-dev libcyaml-dev libyaml-dev libcmocka-dev libcjson-dev \
              libmnl-dev libgpiod-dev libzstd-dev liblz4-dev zlib1g-dev \
              libapriltag3 libpng-dev libegl-dev libegl-mesa0 libgl1-mesa-dri libcamera-dev \
              libglfw3-dev
AARCH64_PKGS := gcc-aarch64-linux-gnu g++-aarch64-linux-gnu qemu-user \
                $(addsuffix :arm64,$(CROSS_LIBS))
ifdef IS_CROSS
BUILD_PKGS := make pkg-config libapriltag-dev $(AARCH64_PKGS)
TEST_PKGS  :=
else
TEST_PKGS  += $(AARCH64_PKGS)
endif

WARN    := -Wall -Wextra -Werror -Wshadow -Wstrict-prototypes -Wmissing-prototypes
CFLAGS  ?= -O2 -g
CFLAGS  += -std=c11 -D_GNU_SOURCE -pthread $(WARN) -MMD -MP $(IMAGE_CFLAGS)
# Deferred (=): pkg-config runs when a rule needs it, after deps-build has
# installed the packages on a fresh machine.
IMAGE_CFLAGS = $(shell pkg-config --cflags libpng)
# By soname (libapriltag3), native and cross alike: see CROSS_LIBS.
APRILTAG_LIBS := -l:libapriltag.so.3 -l:libapriltag-utils.so.3
CAMERA_LIBS  = $(shell pkg-config --libs libpng) $(APRILTAG_LIBS) -lEGL -lglfw
LDLIBS  = -lmujoco -lcyaml -lyaml -lcjson -lmnl -lgpiod -lzstd -llz4 -lz $(CAMERA_LIBS) -lm -pthread
# C++ only for libcamera, in one file behind a C header, built as a module the
# runtime loads when a board has a libcamera camera (drivers/ps_camera_libcamera.h).
CXXFLAGS ?= -O2 -g
CXXFLAGS += -std=c++17 -D_GNU_SOURCE -pthread -Wall -Wextra -Werror -Wshadow -MMD -MP \
            $(shell pkg-config --cflags libcamera)
SANFLAGS := -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
SAN_DIR  := san
ifdef IS_CROSS
SANFLAGS := # ASan's shadow memory does not map under qemu-user: plain builds there
SAN_DIR  := obj
endif

LIB_SRCS  := $(filter-out rt/main.c,$(wildcard rt/*.c drivers/*.c policy/*.c sim/*.c))
CAMERA_SO := $(BUILD)/libpushstep-libcamera.so
MAIN_SRC  := rt/main.c
FAKE_SRCS := $(wildcard tests/fakes/*.c tests/contract/*.c)
TEST_SRCS := $(wildcard tests/test_*.c)
# Tests that count allocations or page faults, or need full speed, are built
# plain (the allocation guard interposes malloc, which ASan replaces), and
# again with sanitizers as SAN_E2E_BINS below.
NOSAN_TESTS := $(basename $(notdir $(wildcard tests/test_e2e*.c tests/test_guard*.c tests/test_noalloc*.c tests/test_render*.c)))
SAN_TESTS   := $(filter-out $(NOSAN_TESTS),$(basename $(notdir $(TEST_SRCS))))

OBJ      = $(patsubst %.c,$(BUILD)/obj/%.o,$(1))
SANOBJ   = $(patsubst %.c,$(BUILD)/$(SAN_DIR)/%.o,$(1))
LIB_OBJS    := $(call OBJ,$(LIB_SRCS))
LIB_SANOBJS := $(call SANOBJ,$(LIB_SRCS))
FAKE_OBJS    := $(call OBJ,$(FAKE_SRCS))
FAKE_SANOBJS := $(call SANOBJ,$(FAKE_SRCS))
TEST_BINS := $(addprefix $(BUILD)/tests/,$(SAN_TESTS) $(NOSAN_TESTS))
# The same end-to-end and guard tests again with ASan and UBSan, from the
# sanitized objects: build/tests/san/<name> (docs/testing.md says what each
# asserts there; the guard counts through ASan's allocator hooks).
ifndef IS_CROSS
SAN_E2E_BINS := $(addprefix $(BUILD)/tests/san/,$(NOSAN_TESTS))
endif
# The lock-free mailbox's test again under ThreadSanitizer (it checks the
# atomics' memory orders, which ASan cannot).
TSAN_BINS := $(BUILD)/tests/test_mailbox_tsan
# The whole runtime under ThreadSanitizer, for the threads around the loop
# (plant, logger, recorder writer, perception, render):
# tests/test_tsan_threads.sh runs it.
TSAN_PUSHSTEP := $(BUILD)/tsan/pushstep
# The whole runtime under ASan and UBSan, for the end-to-end paths the unit
# tests do not cover (every subcommand, recorder, render, camera, replay):
# tests/test_asan_cli.sh runs it. The allocation-counting tests stay plain.
ASAN_PUSHSTEP := $(BUILD)/san/pushstep
# Tests of the real drivers: they need vcan/vxcan and gpio-mockup, so they run
# inside a Debian kernel booted under qemu (tools/qemu/, docs/testing-hw.md).
HW_SRCS := $(wildcard tests/hw/test_hw_*.c)
HW_BINS := $(patsubst tests/hw/%.c,$(BUILD)/tests/hw/%,$(HW_SRCS))
QEMU_WORK ?= $(BUILD)/qemu

.PHONY: fuzz
.PHONY: all deps deps-build deps-test deps-npm deps-bench deps-train run test test-hw clean format help \
        bench bench-hw train train-clone install deb test-deb aarch64-test-bins soak test-build
all: $(BUILD)/pushstep $(CAMERA_SO)

help:
	@echo "make deps    install missing Debian packages, build and target tools (as root;"
	@echo "             idempotent); make run installs only what building needs,"
	@echo "             make test that and can-utils"
	@echo "make all     build $(BUILD)/pushstep (default)"
	@echo "make run     deps + build + run against the simulated crowd, board sim"
	@echo "             options pass through: make run ARGS=\"--duration 5 --lockstep\""
	@echo "make test    deps + build + run the whole cmocka suite, test-hw included"
	@echo "             (skipped with a message where qemu cannot be installed)"
	@echo "make fuzz    every libFuzzer target (tests/fuzz/) for FUZZ_SECONDS (default 60)"
	@echo "             each (FUZZ_TARGETS=\"fuzz_mit ...\" for some): bench/results/fuzz.json"
	@echo "             and fuzz.md (docs/fuzzing.md)"
	@echo "make test-hw the real drivers (SocketCAN, libgpiod) in a Debian kernel"
	@echo "             booted under qemu with vcan, vxcan and gpio-mockup"
	@echo "make bench   latency beside cyclictest, tick share, bus load, allocations,"
	@echo "             the crowd's cost, camera perception, policy inference and the"
	@echo "             push-recovery grid: bench/results/*.json, summary.md, crowd.md,"
	@echo "             camera.md (docs/latency.md, docs/perception.md, docs/policy.md)"
	@echo "make bench-hw the real drivers' figures in the test VM (e-stop reaction,"
	@echo "             loop reaction, frames per bus): bench/results/hw.json"
	@echo "make soak    SOAK_TICKS (1,000,000) ticks in lockstep among the crowd with a"
	@echo "             random fault every 8 s, each recovered; checks states, limits,"
	@echo "             recorder, memory: bench/results/soak.json, soak.md"
	@echo "make train   train the balance policy on the C environment (CPU, 2 cores):"
	@echo "             one run of TRAIN_ARGS for each line of TRAIN_MEMBERS (its seed"
	@echo "             and options; 20-30 min a run), averaged into"
	@echo "             policy/weights/ps1_stage1.safetensors, on the portable float"
	@echo "             path (docs/policy.md); runs in $(BUILD)/train/memberN/"
	@echo "make train-clone the recipe of the file shipped until 2026-12-04 (about 17"
	@echo "             min): $(BUILD)/train/clone.safetensors"
	@echo "make install PREFIX=/usr/local [DESTDIR=]: the binary, its data (boards, robots,"
	@echo "             scenarios, models) in PREFIX/share/pushstep, the systemd unit"
	@echo "             pushstep@.service and the udev rules (docs/deploy.md)"
	@echo "make deb [ARCH=aarch64]: the Debian package (dpkg-buildpackage, packaging in"
	@echo "             tools/debian/) in $(BUILD)/deb/; make test-deb also checks its"
	@echo "             contents and runs the packaged binary"
	@echo "make format  clang-format every C source in place"
	@echo "make clean   remove $(BUILD)/"

deps: deps-build
	@bash tools/deps.sh $(TOOL_PKGS)

deps-build:
	@bash tools/deps.sh $(BUILD_PKGS)

deps-test: deps-build
	@bash tools/deps.sh $(TEST_PKGS)

# The recorder tests read the MCAP files with Foxglove's own readers (npm
# packages pinned in tests/mcap/package.json, installed into $(BUILD)/npm;
# Debian's nodejs and npm when there is no node).
deps-npm:
	@bash tools/npm-deps.sh $(BUILD)/npm

deps-bench: deps
	@bash tools/deps.sh $(BENCH_PKGS)

deps-train: deps-build
	@bash tools/deps.sh $(TRAIN_PKGS)

$(BUILD)/obj/%.o: %.c
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -c $< -o $@

ifndef IS_CROSS
$(BUILD)/san/%.o: %.c
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) $(SANFLAGS) -c $< -o $@
endif

$(BUILD)/pic/%.o: %.cpp
	@mkdir -p $(@D)
	$(CXX) $(CXXFLAGS) -fPIC -c $< -o $@

$(BUILD)/pic/%.o: %.c
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -fPIC -c $< -o $@

$(CAMERA_SO): $(BUILD)/pic/drivers/ps_camera_libcamera.o $(BUILD)/pic/drivers/ps_camera.o
	$(CXX) $(LDFLAGS) -shared -o $@ $^ $(shell pkg-config --libs libcamera) -pthread

$(BUILD)/tsan/%.o: %.c
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -O1 -fsanitize=thread -c $< -o $@

# The inference engine picks its vector width through an ifunc (target_clones),
# resolved before ThreadSanitizer's runtime starts: instrumented, the resolver
# crashes. It shares nothing between threads, so it is built plain.
$(BUILD)/tsan/policy/ps_mlp.o: policy/ps_mlp.c
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -O3 -c $< -o $@

$(ASAN_PUSHSTEP): $(BUILD)/san/rt/main.o $(LIB_SANOBJS)
	$(CC) $(CFLAGS) $(SANFLAGS) $(LDFLAGS) -o $@ $^ $(LDLIBS)

$(TSAN_PUSHSTEP): $(patsubst %.c,$(BUILD)/tsan/%.o,$(MAIN_SRC) $(LIB_SRCS))
	$(CC) $(CFLAGS) -fsanitize=thread $(LDFLAGS) -o $@ $^ $(LDLIBS)

$(BUILD)/tests/test_mailbox_tsan: tests/test_mailbox.c rt/ps_mailbox.c
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -fsanitize=thread -o $@ $^ -lcmocka

# The inference engine's axpy loops vectorise at -O3; GCC 12's -O2 cost model
# leaves them scalar (docs/policy.md): only this file.
$(BUILD)/obj/policy/ps_mlp.o $(BUILD)/san/policy/ps_mlp.o $(BUILD)/pic/policy/ps_mlp.o: CFLAGS += -O3

# The training environment (tools/psenv, docs/policy.md): the runtime's
# sources built position-independent into one library for ctypes.
PIC_OBJS := $(patsubst %.c,$(BUILD)/pic/%.o,$(LIB_SRCS) tools/psenv/ps_env.c)
$(BUILD)/libpsenv.so: $(PIC_OBJS)
	$(CC) $(CFLAGS) -shared -o $@ $^ $(LDLIBS)

$(BUILD)/pushstep: $(call OBJ,$(MAIN_SRC)) $(LIB_OBJS)
	$(CC) $(CFLAGS) $(LDFLAGS) -o $@ $^ $(LDLIBS)

$(addprefix $(BUILD)/tests/,$(SAN_TESTS)): $(BUILD)/tests/%: $(BUILD)/$(SAN_DIR)/tests/%.o $(LIB_SANOBJS) $(FAKE_SANOBJS)
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) $(SANFLAGS) -o $@ $^ $(LDLIBS) -lcmocka

$(addprefix $(BUILD)/tests/,$(NOSAN_TESTS)): $(BUILD)/tests/%: $(BUILD)/obj/tests/%.o $(LIB_OBJS) $(FAKE_OBJS)
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -o $@ $^ $(LDLIBS) -lcmocka

$(SAN_E2E_BINS): $(BUILD)/tests/san/%: $(BUILD)/san/tests/%.o $(LIB_SANOBJS) $(FAKE_SANOBJS)
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) $(SANFLAGS) -o $@ $^ $(LDLIBS) -lcmocka

$(HW_BINS): $(BUILD)/tests/hw/%: $(BUILD)/obj/tests/hw/%.o $(LIB_OBJS) $(FAKE_OBJS)
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -o $@ $^ $(LDLIBS) -lcmocka

# ---- fuzzing (docs/fuzzing.md) --------------------------------------------
# libFuzzer targets, one file each in tests/fuzz/, built with Debian's clang
# and AddressSanitizer + UBSan. The parsers they call are built again with
# coverage into an archive (only the modules of outside input and what they
# need), so a target links only what it uses.
FUZZ_CC      ?= clang-14
FUZZ_CFLAGS  := -O1 -g -std=c11 -D_GNU_SOURCE -pthread $(WARN) -MMD -MP -fno-omit-frame-pointer
FUZZ_SAN     := -fsanitize=address,undefined -fno-sanitize-recover=undefined
FUZZ_LIB_SRCS := drivers/ps_actuator.c drivers/ps_mit.c drivers/ps_robstride.c drivers/ps_moteus.c \
                 drivers/ps_imu.c drivers/ps_imu_msg.c drivers/ps_imu_xsens.c drivers/ps_candump.c \
                 drivers/ps_can_replay.c drivers/ps_gpio_gpiod.c drivers/ps_camera.c drivers/ps_canbus.c \
                 $(wildcard policy/*.c) \
                 rt/ps_err.c rt/ps_clock.c rt/ps_config_board.c rt/ps_config_common.c \
                 rt/ps_config_robot.c rt/ps_config_scenario.c rt/ps_mcap.c rt/ps_rosmsg.c \
                 rt/ps_reclog.c rt/ps_args.c rt/ps_sm.c sim/ps_crowd.c sim/ps_social.c
FUZZ_SRCS    := $(wildcard tests/fuzz/fuzz_*.c)
FUZZ_BINS    := $(patsubst tests/fuzz/%.c,$(BUILD)/fuzz/%,$(FUZZ_SRCS))
FUZZ_LIB     := $(BUILD)/fuzz/libps_fuzz.a
FUZZ_LDLIBS  := -lmujoco -lcyaml -lyaml -lcjson -lgpiod -lmnl -lzstd -llz4 -lz -lm -pthread
FUZZ_SECONDS ?= 60

$(BUILD)/fuzz/obj/%.o: %.c
	@mkdir -p $(@D)
	$(FUZZ_CC) $(FUZZ_CFLAGS) $(FUZZ_SAN) -fsanitize=fuzzer-no-link -c $< -o $@

$(FUZZ_LIB): $(patsubst %.c,$(BUILD)/fuzz/obj/%.o,$(FUZZ_LIB_SRCS))
	@rm -f $@
	ar rcs $@ $^

$(FUZZ_BINS): $(BUILD)/fuzz/%: tests/fuzz/%.c $(FUZZ_LIB)
	$(FUZZ_CC) $(FUZZ_CFLAGS) $(FUZZ_SAN) -fsanitize=fuzzer -MF $(BUILD)/fuzz/obj/$(@F).d -o $@ $< $(FUZZ_LIB) $(FUZZ_LDLIBS)

# make fuzz: every target (or FUZZ_TARGETS, e.g. "fuzz_mit fuzz_mcap") for
# FUZZ_SECONDS (default 60) from its seeds and what earlier runs found
# ($(BUILD)/fuzz/corpus), into bench/results/fuzz.json and fuzz.md (each
# target's latest run); crashes are kept in $(BUILD)/fuzz/crashes.
FUZZ_TARGETS ?= $(notdir $(FUZZ_BINS))
fuzz: deps-test
	@$(MAKE) --no-print-directory -j$(or $(NPROC),1) $(addprefix $(BUILD)/fuzz/,$(FUZZ_TARGETS))
	@BUILD=$(BUILD) FUZZ_SECONDS=$(FUZZ_SECONDS) bash tools/fuzz.sh \
	    $(addprefix $(BUILD)/fuzz/,$(FUZZ_TARGETS))

run: deps-build $(BUILD)/pushstep $(CAMERA_SO)
	$(BUILD)/pushstep --board sim $(ARGS)

ifdef IS_CROSS
test: deps-test $(BUILD)/pushstep $(CAMERA_SO) $(TEST_BINS)
	@PUSHSTEP_BIN=$(BUILD)/pushstep bash tools/test-aarch64.sh $(TEST_BINS)

aarch64-test-bins: $(BUILD)/pushstep $(CAMERA_SO) $(TEST_BINS)
else
# The native suite, then the quick part of the aarch64 one under qemu-user
# (tools/test-aarch64.sh) when the cross tools are installed (deps-test
# installs them where apt can), then the VM tests. The packages first, then
# the builds (plain, sanitized, aarch64) on every CPU: a sub-make, so that
# no compiler starts before its headers are installed.
NPROC := $(shell nproc 2>/dev/null || echo 1)
test: deps-test
	@$(MAKE) --no-print-directory -j$(NPROC) test-build
	@# without the npm packages the rest of the suite still runs; the reader
	@# check then fails (tests/test_e2e_recorder.c) and says why
	@bash tools/npm-deps.sh $(BUILD)/npm || echo "make test: continuing without the MCAP readers"
	@PUSHSTEP_BIN=$(BUILD)/pushstep PUSHSTEP_NPM=$(BUILD)/npm QEMU_WORK=$(QEMU_WORK) \
	    HW_BINS="$(HW_BINS)" AARCH64_BUILD=$(AARCH64_BUILD) BUILD=$(BUILD) FUZZ_BINS="$(FUZZ_BINS)" \
	    PUSHSTEP_SAN_BIN=$(ASAN_PUSHSTEP) bash tools/run-tests.sh \
	    tools/check-layers.sh $(TEST_BINS) $(SAN_E2E_BINS) $(TSAN_BINS) tests/test_tsan_threads.sh \
	    tests/test_asan_cli.sh \
	    tests/test_soak_short.sh policy/train/test_tools.py tests/test_push_bench.py \
	    tests/test_train_smoke.sh tests/test_fuzz.sh tools/test-install.sh tools/test-aarch64.sh \
	    tools/qemu/test-hw.sh

test-build: $(BUILD)/pushstep $(CAMERA_SO) $(BUILD)/libpsenv.so $(TEST_BINS) $(SAN_E2E_BINS) $(TSAN_BINS) \
            $(TSAN_PUSHSTEP) $(ASAN_PUSHSTEP) $(HW_BINS) $(FUZZ_BINS) aarch64-test-bins

AARCH64_BUILD := build-aarch64
aarch64-test-bins:
	@if command -v aarch64-linux-gnu-gcc >/dev/null && command -v qemu-aarch64 >/dev/null && \
	    [ -e /usr/lib/aarch64-linux-gnu/libmujoco.so ] && [ -e /usr/lib/aarch64-linux-gnu/libcmocka.so ] && \
	    [ -e /usr/lib/aarch64-linux-gnu/libzstd.so ] && [ -e /usr/lib/aarch64-linux-gnu/liblz4.so ] && \
	    [ -e /usr/lib/aarch64-linux-gnu/libapriltag.so.3 ] && [ -e /usr/lib/aarch64-linux-gnu/libpng.so ] && \
	    [ -e /usr/lib/aarch64-linux-gnu/libEGL.so ] && [ -e /usr/lib/aarch64-linux-gnu/libcamera.so ] && \
	    [ -e /usr/lib/aarch64-linux-gnu/libglfw.so ]; then \
	    $(MAKE) --no-print-directory ARCH=aarch64 BUILD=$(AARCH64_BUILD) aarch64-test-bins; \
	else echo "aarch64: cross tools or arm64 libraries missing: its tests are skipped"; fi
endif

# The soak (tools/soak.py, docs/safety.md): SOAK_TICKS ticks in lockstep among
# the crowd with a random fault every 8 s; figures into bench/results/soak.*.
SOAK_TICKS ?= 1000000
soak: deps-test $(BUILD)/pushstep
	python3 tools/soak.py --ticks $(SOAK_TICKS) --results bench/results

test-hw: deps-test $(BUILD)/pushstep $(CAMERA_SO) $(HW_BINS)
	@PUSHSTEP_BIN=$(BUILD)/pushstep QEMU_WORK=$(QEMU_WORK) HW_BINS="$(HW_BINS)" bash tools/run-tests.sh tools/qemu/test-hw.sh

bench: deps-bench $(BUILD)/pushstep $(CAMERA_SO) $(BUILD)/crowd_bench $(BUILD)/tests/test_e2e_faults
	@bash bench/run.sh
	@BUILD=$(BUILD) bash bench/faults.sh
	@BUILD=$(BUILD) bash bench/crowd.sh
	@BUILD=$(BUILD) bash bench/camera.sh
	@bash bench/policy.sh
	@QEMU_WORK=$(QEMU_WORK) bash bench/hw.sh

# The simulated crowd's cost (bench/crowd.sh): plant with N agents beside mj_step.
$(BUILD)/crowd_bench: $(call OBJ,bench/crowd_bench.c) $(LIB_OBJS)
	$(CC) $(CFLAGS) -o $@ $^ $(LDLIBS)

# The balance policy's training (docs/policy.md): seeded, on the CPUs, one
# run of a recipe (TRAIN_ARGS) for each line of TRAIN_MEMBERS (its seed and
# any further options; the shipped file's list names r16, r39 and r15 of
# docs/policy.md, seeds 2, 5 and 1, and r41, seed 5 with a cost on the
# stance's width, with their recorded files and logs, which the tests check),
# averaged by policy/train/ensemble.py (one MLP computing the mean of the
# runs; the file keeps the first member's observation normalisation), which
# gives the shipped file from the recorded ones bit for bit. train.py runs on
# the portable float path (policy/train/portable.py), where the recorded
# members, trained on machines of another kind, are not made again
# (docs/policy.md). The recipe: PPO of a residual on the
# capture-point controller (--residual: the policy's actions are added to
# the controller's; it starts as the controller) over 1,000 iterations, 70 %
# of the episodes starting as the runtime's trials do (limp in the harness,
# the servo layer's ramp: --ramp-start), half of the episodes' push from a
# staircase per direction and duration (--stair-p 0.5) and a cost on the hip
# roll residual while the controller swings a foot (--swing-cost 2).
# The commands and seeds are written into the policy file's contract. `make train-clone` runs the recipe of the file
# shipped until 2026-12-04 (cloning the capture-point controller with its
# tunables before its 2026-12-03 change, PPO: TRAIN_CLONE_ARGS; then PPO
# fine-tuning from that file: TRAIN_FT_ARGS), into
# $(BUILD)/train/clone.safetensors; it reproduced that file bit for bit
# before train.py's portable float path (2026-12-07), and has not been run
# whole on it.
TRAIN_MEMBERS ?= policy/weights/ps1_stage1.members
TRAIN_ARGS ?= --envs 16 --threads 2 --steps 64 --bc-iters 0 --ppo-iters 1000 \
              --push-dv-start 0.3 --push-dv-max 0.7 --residual --bc-weight 0 --ppo-lr 1e-4 \
              --gamma 0.995 --gae-lambda 0.98 --harness-p 0.7 --ramp-start --stair-p 0.5 \
              --swing-cost 2
TRAIN_CLONE_ARGS ?= --seed 1 --envs 16 --threads 2 --steps 64 --bc-iters 100 --ppo-iters 600 \
              --push-dv-max 0.6 --expert slow
TRAIN_FT_ARGS ?= --seed 2 --envs 16 --threads 2 --steps 64 --bc-iters 0 --ppo-iters 320 \
              --critic-warmup 40 --bc-weight 0.2 --harness-p 0.5 --push-dv-min 0.05 \
              --push-dv-start 0.6 --push-dv-max 0.6 --ppo-lr 3e-5 --focus-p 0.3 \
              --gamma 0.995 --gae-lambda 0.98 --fixed-std --expert slow
# The list is copied before the first run and read from the copy: the loop
# reads it a line at a time, and an edit to it during the hours of training
# once shifted the next read into the middle of a line.
train: deps-train $(BUILD)/pushstep $(BUILD)/libpsenv.so
	set -e; n=0; runs=; mkdir -p $(BUILD)/train; \
	cp $(TRAIN_MEMBERS) $(BUILD)/train/members; \
	while read -r seed file log opts; do \
	    case "$$seed" in ''|'#'*) continue ;; esac; \
	    n=$$((n + 1)); d=$(BUILD)/train/member$$n; \
	    /usr/bin/python3 policy/train/train.py $(TRAIN_ARGS) --seed $$seed $$opts \
	        --out $$d/policy.safetensors --log-dir $$d </dev/null; \
	    runs="$$runs $$d/policy.safetensors"; \
	done <$(BUILD)/train/members; \
	test -n "$$runs" || { echo "$(TRAIN_MEMBERS): no member" >&2; exit 1; }; \
	/usr/bin/python3 policy/train/ensemble.py --out policy/weights/ps1_stage1.safetensors $$runs
train-clone: deps-train $(BUILD)/pushstep $(BUILD)/libpsenv.so
	/usr/bin/python3 policy/train/train.py $(TRAIN_CLONE_ARGS) --out $(BUILD)/train/first.safetensors \
	    --log-dir $(BUILD)/train/first
	/usr/bin/python3 policy/train/train.py $(TRAIN_FT_ARGS) --init $(BUILD)/train/first.safetensors \
	    --out $(BUILD)/train/clone.safetensors --log-dir $(BUILD)/train/finetune

bench-hw: deps-test $(BUILD)/pushstep
	@QEMU_WORK=$(QEMU_WORK) bash bench/hw.sh

# Installation (docs/deploy.md). The data the binary looks up by name go to
# PREFIX/share/pushstep, where an installed PREFIX/bin/pushstep finds them.
PREFIX   ?= /usr/local
DESTDIR  ?=
BINDIR   := $(PREFIX)/bin
DATADIR  := $(PREFIX)/share/pushstep
DOCDIR   := $(PREFIX)/share/doc/pushstep
UNITDIR  ?= $(PREFIX)/lib/systemd/system
UDEVDIR  ?= $(PREFIX)/lib/udev/rules.d
# Trained policy files (policy/weights/, written by make train) are data too:
# a robot file's policy.weights names one relative to the robot file.
DATA_DIRS := boards robots scenarios sim/models $(wildcard policy/weights)

install: $(BUILD)/pushstep $(CAMERA_SO)
	install -D -m 0755 $(BUILD)/pushstep $(DESTDIR)$(BINDIR)/pushstep
	install -D -m 0644 $(CAMERA_SO) $(DESTDIR)$(PREFIX)/lib/pushstep/libpushstep-libcamera.so
	for d in $(DATA_DIRS); do install -d $(DESTDIR)$(DATADIR)/$$d && \
	    cp -R --no-preserve=mode,ownership $$d/. $(DESTDIR)$(DATADIR)/$$d/ || exit 1; done
	install -D -m 0755 tools/plot-profile.sh $(DESTDIR)$(DATADIR)/tools/plot-profile.sh
	install -d $(DESTDIR)$(UNITDIR) $(DESTDIR)$(UDEVDIR) $(DESTDIR)$(DOCDIR)
	sed -e 's|@BINDIR@|$(BINDIR)|g' -e 's|@DOCDIR@|$(DOCDIR)|g' tools/systemd/pushstep@.service \
	    > $(DESTDIR)$(UNITDIR)/pushstep@.service
	install -m 0644 tools/udev/60-pushstep.rules $(DESTDIR)$(UDEVDIR)/60-pushstep.rules
	install -m 0644 README.md docs/deploy.md docs/config.md $(DESTDIR)$(DOCDIR)/

# The Debian package (tools/make-deb.sh). DEB_PKGS: what building it needs.
DEB_PKGS := build-essential dpkg-dev debhelper fakeroot
ifdef IS_CROSS
DEB_PKGS += crossbuild-essential-arm64
endif

deb: deps-build
	@bash tools/deps.sh $(DEB_PKGS)
	@bash tools/make-deb.sh build $(DEB_ARCH)

test-deb: deb
	@bash tools/deps.sh lintian
	@PUSHSTEP_DEB_DIR=build/deb PUSHSTEP_DEB_ARCH=$(DEB_ARCH) bash tools/run-tests.sh tools/test-deb.sh

format:
	clang-format -i $$(git ls-files '*.c' '*.h')

clean:
	rm -rf $(BUILD)

-include $(shell find $(BUILD)/obj $(BUILD)/san $(BUILD)/pic $(BUILD)/tsan $(BUILD)/fuzz -name '*.d' -type f 2>/dev/null)
