# The ECU firmware for the STM32F405/407: `make firmware` from the repository root.
# Debian's arm-none-eabi-gcc and newlib-nano; nothing is downloaded.
# Out: build/fw/topdress-ecu-stm32f4.{elf,bin,hex,map}, and the flash, RAM and stack figures.
CC := arm-none-eabi-gcc
OBJCOPY := arm-none-eabi-objcopy
OUT := build/fw
NAME := topdress-ecu-stm32f4
PORT := ecu/ports/stm32f4
SRC := $(wildcard ecu/src/*.c) ecu/src/gen/td_can.c $(wildcard ecu/ports/common/*.c) \
       ecu/ports/common/gen/td_hilcan.c $(wildcard $(PORT)/*.c)
OBJ := $(patsubst %.c,$(OUT)/obj/%.o,$(SRC))
CPU := -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16
# -fno-math-errno: sqrtf is the FPU's VSQRT (the core never reads errno)
CFLAGS := $(CPU) -std=c99 -Os -g -fno-math-errno -ffunction-sections -fdata-sections \
          -Wall -Wextra -Werror -pedantic -Wdouble-promotion -Wshadow \
          -fstack-usage -fcallgraph-info=su \
          -Iecu/include -Iecu/src/gen -Iecu/ports/common -Iecu/ports/common/gen -I$(PORT) $(FW_CFLAGS)
LDFLAGS := $(CPU) -nostartfiles --specs=nano.specs --specs=nosys.specs -Wl,--gc-sections \
           -T$(PORT)/stm32f405.ld -Wl,-Map=$(OUT)/$(NAME).map

.PHONY: all
all: $(OUT)/$(NAME).bin $(OUT)/$(NAME).hex
	python3 scripts/fw_report.py $(OUT)/$(NAME).elf $(OUT)/obj

$(OUT)/$(NAME).elf: $(OBJ) $(PORT)/stm32f405.ld
	$(CC) $(LDFLAGS) $(OBJ) -lm -o $@

$(OUT)/%.bin: $(OUT)/%.elf
	$(OBJCOPY) -O binary $< $@

$(OUT)/%.hex: $(OUT)/%.elf
	$(OBJCOPY) -O ihex $< $@

# the generated codecs convert through double on purpose (cantools)
$(OUT)/obj/%/gen/td_can.o $(OUT)/obj/%/gen/td_hilcan.o: CFLAGS += -Wno-double-promotion

$(OUT)/obj/%.o: %.c $(wildcard ecu/include/*.h ecu/src/gen/*.h ecu/ports/common/*.h $(PORT)/*.h) $(MAKEFILE_LIST)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -c $< -o $@
