# The ATmega2560 port (simulated in simavr) and its measurements; included by firmware/Makefile.
#   make -C firmware avr          build/avr/pfw_avr.elf (+ .hex), the size report build/avr/size.txt, the
#                                 per-function stack report build/avr/stack_usage.txt
#   make -C firmware avr-sim      build/avr/pfw_simavr: the simavr harness (needs libsimavr-dev, libelf-dev)
#   make -C firmware avr-timing   the constructed worst-case step, run in simavr: build/avr/timing.json
#   make -C firmware avr-stack    the firmware idle for 2 s in simavr, stack high-water mark: build/avr/idle.json
#   make -C firmware avr-check    avr + avr-timing, and the size limits of the dsPIC30F6014 checked
#   make -C firmware avr-events   build/avr/pfw_avr_events.elf: the firmware reporting its fin events on USART1, for
#                                 an emulated fish that follows the simulated microcontroller (sim/simavr_core.py)
# Needs the Debian packages gcc-avr, avr-libc, binutils-avr (and for the simulator simavr, libsimavr-dev,
# libelf-dev, pkg-config).
AVR_CC ?= avr-gcc
AVR_SIZE ?= avr-size
AVR_NM ?= avr-nm
AVR_OBJCOPY ?= avr-objcopy
AVR_MCU := atmega2560
AVR_F_CPU := 16000000UL
AVR_BUILD := $(BUILD)/avr
AVR_DIR := ports/avr
# The core's host build adds -Wconversion -Wdouble-promotion; avr-gcc 5.4 warns there where avr-libc's float
# functions return double (32-bit on AVR: no promotion happens) and on uint8_t arithmetic that int16 cannot overflow.
AVR_CFLAGS := -mmcu=$(AVR_MCU) -DF_CPU=$(AVR_F_CPU) -std=c99 -Wall -Wextra -Werror -pedantic -Wshadow \
	-Wstrict-prototypes -Os -ffunction-sections -fdata-sections -fstack-usage \
	-Icore/include -Icore/src -I$(AVR_DIR) -Iports/common
AVR_LDFLAGS := -mmcu=$(AVR_MCU) -Wl,--gc-sections -Wl,-Map,$(AVR_BUILD)/pfw_avr.map
AVR_PORT_SRC := $(AVR_DIR)/hal_avr.c ports/common/boot_id.c
AVR_HDR := $(CORE_HDR) $(AVR_DIR)/hal_avr.h ports/common/boot_id.h
AVR_CORE_OBJ := $(patsubst core/src/%.c,$(AVR_BUILD)/core/%.o,$(CORE_SRC))
AVR_PORT_OBJ := $(AVR_BUILD)/hal_avr.o $(AVR_BUILD)/hal_avr_init.o $(AVR_BUILD)/boot_id.o
SIM := $(AVR_BUILD)/pfw_simavr
SIM_SRC := $(AVR_DIR)/sim/pfw_simavr.c $(AVR_DIR)/sim/xbee_pair.c $(AVR_DIR)/sim/xbee_pair.h
# The dsPIC30F6014's budget (the robot's microcontroller): 144 KB of program flash, 8 KB of RAM.
DSPIC_FLASH := 147456
DSPIC_RAM := 8192

.PHONY: avr avr-sim avr-timing avr-stack avr-check avr-events avr-clean

avr: $(AVR_BUILD)/pfw_avr.elf $(AVR_BUILD)/pfw_avr.hex $(AVR_BUILD)/size.txt $(AVR_BUILD)/stack_usage.txt
	@cat $(AVR_BUILD)/size.txt

$(AVR_BUILD)/core/%.o: core/src/%.c $(AVR_HDR) $(AVR_DIR)/avr.mk
	@mkdir -p $(AVR_BUILD)/core
	$(AVR_CC) $(AVR_CFLAGS) -c -o $@ $<

$(AVR_BUILD)/hal_avr.o: $(AVR_DIR)/hal_avr.c $(AVR_HDR) $(AVR_DIR)/avr.mk
	@mkdir -p $(AVR_BUILD)
	$(AVR_CC) $(AVR_CFLAGS) -c -o $@ $<

$(AVR_BUILD)/hal_avr_init.o: $(AVR_DIR)/hal_avr_init.S $(AVR_DIR)/avr.mk
	@mkdir -p $(AVR_BUILD)
	$(AVR_CC) -mmcu=$(AVR_MCU) -c -o $@ $<

$(AVR_BUILD)/boot_id.o: ports/common/boot_id.c $(AVR_HDR) $(AVR_DIR)/avr.mk
	@mkdir -p $(AVR_BUILD)
	$(AVR_CC) $(AVR_CFLAGS) -c -o $@ $<

$(AVR_BUILD)/%_avr.o: $(AVR_DIR)/%_avr.c $(AVR_HDR) $(AVR_DIR)/avr.mk
	@mkdir -p $(AVR_BUILD)
	$(AVR_CC) $(AVR_CFLAGS) -c -o $@ $<

$(AVR_BUILD)/pfw_avr.elf: $(AVR_BUILD)/main_avr.o $(AVR_PORT_OBJ) $(AVR_CORE_OBJ)
	$(AVR_CC) $(AVR_LDFLAGS) -o $@ $^ -lm

$(AVR_BUILD)/main_avr_events.o: $(AVR_DIR)/main_avr.c $(AVR_HDR) $(AVR_DIR)/avr.mk
	@mkdir -p $(AVR_BUILD)
	$(AVR_CC) $(AVR_CFLAGS) -DPFW_AVR_EVENTS -c -o $@ $<

$(AVR_BUILD)/pfw_avr_events.elf: $(AVR_BUILD)/main_avr_events.o $(AVR_PORT_OBJ) $(AVR_CORE_OBJ)
	$(AVR_CC) $(AVR_LDFLAGS:pfw_avr.map=pfw_avr_events.map) -o $@ $^ -lm

avr-events: $(AVR_BUILD)/pfw_avr_events.elf $(SIM)

$(AVR_BUILD)/pfw_avr_timing.elf: $(AVR_BUILD)/timing_avr.o $(AVR_PORT_OBJ) $(AVR_CORE_OBJ)
	$(AVR_CC) $(AVR_LDFLAGS:pfw_avr.map=pfw_avr_timing.map) -o $@ $^ -lm

$(AVR_BUILD)/pfw_avr.hex: $(AVR_BUILD)/pfw_avr.elf
	$(AVR_OBJCOPY) -O ihex -R .eeprom $< $@

# Flash = .text + .data (initial values live in flash); static RAM = .data + .bss; the rest of the RAM is stack.
$(AVR_BUILD)/size.txt: $(AVR_BUILD)/pfw_avr.elf
	$(AVR_SIZE) -A $< > $@.tmp
	@awk -v flash=$(DSPIC_FLASH) -v ram=$(DSPIC_RAM) \
	  '$$1==".text"{t=$$2} $$1==".data"{d=$$2} $$1==".bss"{b=$$2} END{ \
	   printf "flash %d bytes (%.1f %% of the dsPIC30F6014s %d), static RAM %d bytes (%.1f %% of %d): data %d, bss %d\n", \
	   t+d, 100*(t+d)/flash, flash, d+b, 100*(d+b)/ram, ram, d, b }' $@.tmp > $@
	@rm -f $@.tmp

# -fstack-usage: each function's own frame (a call chain's depth is the sum along it; avr-idle measures the peak).
$(AVR_BUILD)/stack_usage.txt: $(AVR_BUILD)/pfw_avr.elf
	@cat $(AVR_BUILD)/core/*.su $(AVR_BUILD)/*.su | sort -t'	' -k2 -n -r > $@

$(SIM): $(SIM_SRC)
	@mkdir -p $(AVR_BUILD)
	$(CC) -std=c99 -Wall -Wextra -Werror -O2 -o $@ $(AVR_DIR)/sim/pfw_simavr.c $(AVR_DIR)/sim/xbee_pair.c \
	  $$(pkg-config --cflags --libs simavr) -lelf

avr-sim: $(SIM)

avr-timing: $(AVR_BUILD)/pfw_avr_timing.elf $(SIM)
	$(SIM) --report $(AVR_BUILD)/timing.json \
	  --stack-floor 0x$$($(AVR_NM) $< | awk '$$3=="_end"{print $$1}' | sed 's/^0*80//') $<
	@cat $(AVR_BUILD)/timing.json

avr-stack: $(AVR_BUILD)/pfw_avr.elf $(SIM)
	$(SIM) --run-ms 2000 --report $(AVR_BUILD)/idle.json \
	  --stack-floor 0x$$($(AVR_NM) $< | awk '$$3=="_end"{print $$1}' | sed 's/^0*80//') $<
	@cat $(AVR_BUILD)/idle.json

avr-check: avr avr-timing
	@awk -v flash=$(DSPIC_FLASH) -v ram=$(DSPIC_RAM) '{ f=$$2; r=$$12 } END { \
	  if (f > flash || r > ram) { print "avr-check: over the dsPIC30F6014 budget"; exit 1 } }' $(AVR_BUILD)/size.txt
	@echo "avr-check: flash and static RAM within the dsPIC30F6014's 144 KB / 8 KB"

avr-clean:
	rm -rf $(AVR_BUILD)
