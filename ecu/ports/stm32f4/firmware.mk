# The ECU firmware for the STM32F405/407: `make firmware` from the repository root.
# Debian's arm-none-eabi-gcc and newlib-nano; nothing is downloaded.
#
#   BOARD=generic8 (default) | olimex_e407 | olimex_p407   the board header boards/$(BOARD).h
#   VARIANT=board (default) | qemu                         qemu: the emulator build (SLCAN/HIL on
#                                                          USART1, no clock set-up, the generic
#                                                          board), never flashed
#   FW_ISOBUS=1                                            the ISOBUS node (ecu/isobus) beside the
#                                                          core: the TC commands it (docs/isobus.md);
#                                                          out: build/fw-isobus/, build/fw-qemu-isobus/
#   FW_CFLAGS=-DBOARD_CAN_BITRATE=500000                   a board header's guarded default
# Out: build/fw/topdress-ecu-stm32f4.{elf,bin,hex,map} for the default board, build/fw-$(BOARD)/
# for another, build/fw-qemu/ for the emulator build; the flash, RAM and stack figures.
CC := arm-none-eabi-gcc
OBJCOPY := arm-none-eabi-objcopy
BOARD ?= generic8
VARIANT ?= board
NAME := topdress-ecu-stm32f4
PORT := ecu/ports/stm32f4
ifeq ($(VARIANT),qemu)
override BOARD := generic8
OUT ?= build/fw-qemu
VARIANT_FLAGS := -DFW_QEMU=1
else ifeq ($(VARIANT),board)
OUT ?= $(if $(filter generic8,$(BOARD)),build/fw,build/fw-$(BOARD))
VARIANT_FLAGS :=
else
$(error VARIANT=$(VARIANT): board or qemu)
endif
FW_ISOBUS ?= 0
ifeq ($(FW_ISOBUS),1)
OUT := $(if $(filter qemu,$(VARIANT)),build/fw-qemu-isobus,$(if $(filter generic8,$(BOARD)),build/fw-isobus,build/fw-isobus-$(BOARD)))
VARIANT_FLAGS += -DFW_ISOBUS=1
ISOBUS_SRC := $(wildcard ecu/isobus/src/*.c) ecu/isobus/src/gen/td_ddop_gen.c
ISOBUS_INC := -Iecu/isobus/include -Iecu/isobus/src/gen
else ifneq ($(FW_ISOBUS),0)
$(error FW_ISOBUS=$(FW_ISOBUS): 0 or 1)
endif
ifeq ($(wildcard $(PORT)/boards/$(BOARD).h),)
$(error BOARD=$(BOARD): no $(PORT)/boards/$(BOARD).h (docs/firmware.md, adding a board))
endif
SRC := $(wildcard ecu/src/*.c) ecu/src/gen/td_can.c $(wildcard ecu/ports/common/*.c) \
       ecu/ports/common/gen/td_hilcan.c $(wildcard $(PORT)/*.c) $(ISOBUS_SRC)
OBJ := $(patsubst %.c,$(OUT)/obj/%.o,$(SRC))
CPU := -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16
# -fno-math-errno: sqrtf is the FPU's VSQRT (the core never reads errno)
CFLAGS := $(CPU) -std=c99 -Os -g -fno-math-errno -ffunction-sections -fdata-sections \
          -Wall -Wextra -Werror -pedantic -Wconversion -Wsign-conversion -Wswitch-enum \
          -Wcast-align -Wshadow -Wundef -Wdouble-promotion \
          -fstack-usage -fcallgraph-info=su \
          -DBOARD_HEADER='"boards/$(BOARD).h"' $(VARIANT_FLAGS) \
          -Iecu/include -Iecu/src/gen -Iecu/ports/common -Iecu/ports/common/gen -I$(PORT) $(ISOBUS_INC) $(FW_CFLAGS)
LDFLAGS := $(CPU) -nostartfiles --specs=nano.specs --specs=nosys.specs -Wl,--gc-sections \
           -T$(PORT)/stm32f405.ld -Wl,-Map=$(OUT)/$(NAME).map

.PHONY: all
all: $(OUT)/$(NAME).bin $(OUT)/$(NAME).hex
	python3 scripts/fw_report.py $(OUT)/$(NAME).elf $(OUT)/obj

# The flags of the last build, rewritten (when they differ) as the makefile is read: every
# object depends on it, so a changed FW_CFLAGS (or board, variant) rebuilds them all and
# `make firmware FW_CFLAGS=...` never ships objects built with other flags.
FLAGS_STAMP := $(OUT)/flags.stamp
$(shell mkdir -p $(OUT) && (echo '$(CFLAGS)' | cmp -s - $(FLAGS_STAMP) || echo '$(CFLAGS)' > $(FLAGS_STAMP)))

$(OUT)/$(NAME).elf: $(OBJ) $(PORT)/stm32f405.ld
	$(CC) $(LDFLAGS) $(OBJ) -lm -o $@

$(OUT)/%.bin: $(OUT)/%.elf
	$(OBJCOPY) -O binary $< $@

$(OUT)/%.hex: $(OUT)/%.elf
	$(OBJCOPY) -O ihex $< $@

# the generated codecs convert through double on purpose (cantools)
$(OUT)/obj/%/gen/td_can.o $(OUT)/obj/%/gen/td_hilcan.o: CFLAGS += -Wno-double-promotion

$(OUT)/obj/%.o: %.c $(wildcard ecu/include/*.h ecu/src/gen/*.h ecu/ports/common/*.h ecu/ports/common/gen/*.h \
                  $(PORT)/*.h $(PORT)/boards/*.h ecu/isobus/include/*.h ecu/isobus/src/gen/*.h) $(MAKEFILE_LIST) $(FLAGS_STAMP)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -c $< -o $@
