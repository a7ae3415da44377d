# pushstep: real-time balance controller runtime.  `make help` lists targets.
.DEFAULT_GOAL := all
SHELL := /bin/bash

BUILD   ?= build
ARGS    ?=
CC      ?= cc
CXX     ?= c++

# Debian 12 packages (README says why each is there). BUILD_PKGS build, test
# and run the system; TOOL_PKGS are for working with targets (cyclictest,
# can-utils, libgpiod, C++ for the camera side). `make deps` installs both.
BUILD_PKGS := gcc libc6-dev make pkg-config libmujoco-dev libcyaml-dev libyaml-dev \
              libcmocka-dev libcjson-dev libmnl-dev libgpiod-dev
TOOL_PKGS  := g++ rt-tests can-utils
# What `make test` needs beyond building: can-utils' log2long reads the
# candump-format lines the runtime writes (tests/test_candump.c); the policy
# tools' tests (policy/train/test_tools.py) run the ONNX importer.
TEST_PKGS  := can-utils python3 python3-numpy python3-onnx python3-hypothesis python3-torch \
              python3-yaml python3-tqdm
# Extra packages `make bench` needs: load generator, plots, the analysis script,
# GNU parallel for the push-recovery grid (bench/push.py).
BENCH_PKGS := stress-ng gnuplot-nox python3 parallel libopenblas-dev libtorch-dev
# What `make train` needs (policy/train/, never at run time).
TRAIN_PKGS := python3 python3-torch python3-numpy python3-yaml python3-tqdm gnuplot-nox

WARN    := -Wall -Wextra -Werror -Wshadow -Wstrict-prototypes -Wmissing-prototypes
CFLAGS  ?= -O2 -g
CFLAGS  += -std=c11 -D_GNU_SOURCE -pthread $(WARN) -MMD -MP
LDLIBS  := -lmujoco -lcyaml -lyaml -lcjson -lmnl -lgpiod -lm -pthread
SANFLAGS := -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined

LIB_SRCS  := $(filter-out rt/main.c,$(wildcard rt/*.c drivers/*.c policy/*.c sim/*.c))
MAIN_SRC  := rt/main.c
FAKE_SRCS := $(wildcard tests/fakes/*.c tests/contract/*.c)
TEST_SRCS := $(wildcard tests/test_*.c)
# Tests that count allocations or page faults, or need full speed, run without
# sanitizers (ASan replaces malloc, which the allocation guard interposes).
NOSAN_TESTS := $(basename $(notdir $(wildcard tests/test_e2e*.c tests/test_guard*.c tests/test_noalloc*.c)))
SAN_TESTS   := $(filter-out $(NOSAN_TESTS),$(basename $(notdir $(TEST_SRCS))))

OBJ      = $(patsubst %.c,$(BUILD)/obj/%.o,$(1))
SANOBJ   = $(patsubst %.c,$(BUILD)/san/%.o,$(1))
LIB_OBJS    := $(call OBJ,$(LIB_SRCS))
LIB_SANOBJS := $(call SANOBJ,$(LIB_SRCS))
FAKE_OBJS    := $(call OBJ,$(FAKE_SRCS))
FAKE_SANOBJS := $(call SANOBJ,$(FAKE_SRCS))
TEST_BINS := $(addprefix $(BUILD)/tests/,$(SAN_TESTS) $(NOSAN_TESTS))
# Tests of the real drivers: they need vcan/vxcan and gpio-mockup, so they run
# inside a Debian kernel booted under qemu (tools/qemu/, docs/testing-hw.md).
HW_SRCS := $(wildcard tests/hw/test_hw_*.c)
HW_BINS := $(patsubst tests/hw/%.c,$(BUILD)/tests/hw/%,$(HW_SRCS))
QEMU_WORK ?= $(BUILD)/qemu

.PHONY: all deps deps-build deps-test deps-bench deps-train run test test-hw clean format help bench bench-hw train
all: $(BUILD)/pushstep

help:
	@echo "make deps    install missing Debian packages, build and target tools (as root;"
	@echo "             idempotent); make run installs only what building needs,"
	@echo "             make test that and can-utils"
	@echo "make all     build $(BUILD)/pushstep (default)"
	@echo "make run     deps + build + run against the simulated crowd, board sim"
	@echo "             options pass through: make run ARGS=\"--duration 5 --lockstep\""
	@echo "make test    deps + build + run the whole cmocka suite, test-hw included"
	@echo "             (skipped with a message where qemu cannot be installed)"
	@echo "make test-hw the real drivers (SocketCAN, libgpiod) in a Debian kernel"
	@echo "             booted under qemu with vcan, vxcan and gpio-mockup"
	@echo "make bench   latency beside cyclictest, tick share, bus load, allocations,"
	@echo "             policy inference and the push-recovery grid (docs/policy.md):"
	@echo "             bench/results/*.json and summary.md (see docs/latency.md)"
	@echo "make bench-hw the real drivers' figures in the test VM (e-stop reaction,"
	@echo "             loop reaction, frames per bus): bench/results/hw.json"
	@echo "make train   train the balance policy on the C environment (CPU, 2 cores,"
	@echo "             seeded): policy/weights/ps1_stage1.safetensors, $(BUILD)/train/"
	@echo "make format  clang-format every C source in place"
	@echo "make clean   remove $(BUILD)/"

deps: deps-build
	@bash tools/deps.sh $(TOOL_PKGS)

deps-build:
	@bash tools/deps.sh $(BUILD_PKGS)

deps-test: deps-build
	@bash tools/deps.sh $(TEST_PKGS)

deps-bench: deps
	@bash tools/deps.sh $(BENCH_PKGS)

deps-train: deps-build
	@bash tools/deps.sh $(TRAIN_PKGS)

$(BUILD)/obj/%.o: %.c
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -c $< -o $@

$(BUILD)/san/%.o: %.c
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) $(SANFLAGS) -c $< -o $@

# The inference engine's axpy loops vectorise at -O3; GCC 12's -O2 cost model
# leaves them scalar (docs/policy.md): only this file.
$(BUILD)/obj/policy/ps_mlp.o $(BUILD)/san/policy/ps_mlp.o $(BUILD)/pic/policy/ps_mlp.o: CFLAGS += -O3

# The training environment (tools/psenv, docs/policy.md): the runtime's
# sources built position-independent into one library for ctypes.
PIC_OBJS := $(patsubst %.c,$(BUILD)/pic/%.o,$(LIB_SRCS) tools/psenv/ps_env.c)
$(BUILD)/pic/%.o: %.c
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -fPIC -c $< -o $@

$(BUILD)/libpsenv.so: $(PIC_OBJS)
	$(CC) $(CFLAGS) -shared -o $@ $^ $(LDLIBS)

$(BUILD)/pushstep: $(call OBJ,$(MAIN_SRC)) $(LIB_OBJS)
	$(CC) $(CFLAGS) -o $@ $^ $(LDLIBS)

$(addprefix $(BUILD)/tests/,$(SAN_TESTS)): $(BUILD)/tests/%: $(BUILD)/san/tests/%.o $(LIB_SANOBJS) $(FAKE_SANOBJS)
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) $(SANFLAGS) -o $@ $^ $(LDLIBS) -lcmocka

$(addprefix $(BUILD)/tests/,$(NOSAN_TESTS)): $(BUILD)/tests/%: $(BUILD)/obj/tests/%.o $(LIB_OBJS) $(FAKE_OBJS)
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -o $@ $^ $(LDLIBS) -lcmocka

$(HW_BINS): $(BUILD)/tests/hw/%: $(BUILD)/obj/tests/hw/%.o $(LIB_OBJS) $(FAKE_OBJS)
	@mkdir -p $(@D)
	$(CC) $(CFLAGS) -o $@ $^ $(LDLIBS) -lcmocka

run: deps-build $(BUILD)/pushstep
	$(BUILD)/pushstep --board sim $(ARGS)

test: deps-test $(BUILD)/pushstep $(BUILD)/libpsenv.so $(TEST_BINS) $(HW_BINS)
	@PUSHSTEP_BIN=$(BUILD)/pushstep QEMU_WORK=$(QEMU_WORK) HW_BINS="$(HW_BINS)" bash tools/run-tests.sh \
	    tools/check-layers.sh $(TEST_BINS) policy/train/test_tools.py tests/test_train_smoke.sh \
	    tools/qemu/test-hw.sh

test-hw: deps-test $(BUILD)/pushstep $(HW_BINS)
	@PUSHSTEP_BIN=$(BUILD)/pushstep QEMU_WORK=$(QEMU_WORK) HW_BINS="$(HW_BINS)" bash tools/run-tests.sh tools/qemu/test-hw.sh

bench: deps-bench $(BUILD)/pushstep
	@bash bench/run.sh
	@bash bench/policy.sh
	@QEMU_WORK=$(QEMU_WORK) bash bench/hw.sh

# The shipped policy, reproduced (docs/policy.md): seeded, on the CPUs. The
# command and seed are written into the policy file's contract.
TRAIN_ARGS ?= --seed 1 --envs 16 --threads 2 --steps 64 --bc-iters 100 --ppo-iters 300
train: deps-train $(BUILD)/pushstep $(BUILD)/libpsenv.so
	/usr/bin/python3 policy/train/train.py $(TRAIN_ARGS) --out policy/weights/ps1_stage1.safetensors \
	    --log-dir $(BUILD)/train

bench-hw: deps-test $(BUILD)/pushstep
	@QEMU_WORK=$(QEMU_WORK) bash bench/hw.sh

format:
	clang-format -i $$(git ls-files '*.c' '*.h')

clean:
	rm -rf $(BUILD)

-include $(shell find $(BUILD)/obj $(BUILD)/san $(BUILD)/pic -name '*.d' -type f 2>/dev/null)
