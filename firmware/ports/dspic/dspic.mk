# The dsPIC30F6014 port (the paper's robot); included by firmware/Makefile.
#   make -C firmware dspic         build/dspic/pfw_dspic.elf and .hex with Microchip XC16 (xc16-gcc on the PATH,
#                                  or XC16_DIR=/opt/microchip/xc16/vX.YY); the memory report build/dspic/memory.txt
#   make -C firmware dspic-check   without XC16: hal_dspic.c, main_dspic.c and config_dspic.c compiled by the host's
#                                  gcc against register stubs (ports/dspic/check), and check_dspic.c run on the HAL
XC16_DIR ?=
XC16_CC := $(if $(XC16_DIR),$(XC16_DIR)/bin/xc16-gcc,xc16-gcc)
XC16_BIN2HEX := $(if $(XC16_DIR),$(XC16_DIR)/bin/xc16-bin2hex,xc16-bin2hex)
DSPIC_BUILD := $(BUILD)/dspic
DSPIC_DIR := ports/dspic
DSPIC_SRC := $(DSPIC_DIR)/main_dspic.c $(DSPIC_DIR)/hal_dspic.c $(DSPIC_DIR)/config_dspic.c ports/common/boot_id.c \
	$(CORE_SRC)
DSPIC_HDR := $(CORE_HDR) $(DSPIC_DIR)/hal_dspic.h ports/common/boot_id.h
# XC16's double is 32-bit by default (as float): the core uses float only. -O1 is the highest level of XC16's
# free edition.
DSPIC_CFLAGS := -mcpu=30F6014 -std=c99 -Wall -Wextra -Werror -O1 -Icore/include -Icore/src -I$(DSPIC_DIR) \
	-Iports/common
DSPIC_LDFLAGS := -Wl,--heap=0,--report-mem,-Map=$(DSPIC_BUILD)/pfw_dspic.map
DSPIC_CHECK_CFLAGS := -std=c99 -Wall -Wextra -Werror -pedantic -Wshadow -O1 -g \
	-fsanitize=address,undefined -fno-sanitize-recover=all \
	-I$(DSPIC_DIR)/check -Icore/include -Icore/src -I$(DSPIC_DIR) -Iports/common

.PHONY: dspic dspic-check

dspic: $(DSPIC_BUILD)/pfw_dspic.hex

$(DSPIC_BUILD)/pfw_dspic.elf: $(DSPIC_SRC) $(DSPIC_HDR) $(DSPIC_DIR)/dspic.mk
	@command -v $(XC16_CC) >/dev/null 2>&1 || { echo "dspic: $(XC16_CC) not found: install Microchip MPLAB XC16" \
	  "(or set XC16_DIR); without it, make -C firmware dspic-check checks the port's C on the host"; exit 1; }
	@mkdir -p $(DSPIC_BUILD)
	$(XC16_CC) $(DSPIC_CFLAGS) -o $@ $(DSPIC_SRC) $(DSPIC_LDFLAGS) > $(DSPIC_BUILD)/memory.txt
	@cat $(DSPIC_BUILD)/memory.txt

$(DSPIC_BUILD)/pfw_dspic.hex: $(DSPIC_BUILD)/pfw_dspic.elf
	$(XC16_BIN2HEX) $<

$(DSPIC_BUILD)/check_dspic: $(DSPIC_DIR)/check/check_dspic.c $(DSPIC_DIR)/hal_dspic.c $(DSPIC_DIR)/check/xc.h \
		$(DSPIC_DIR)/check/libpic30.h ports/common/boot_id.c $(DSPIC_HDR) $(CORE_SRC) $(DSPIC_DIR)/dspic.mk
	@mkdir -p $(DSPIC_BUILD)
	$(CC) $(DSPIC_CHECK_CFLAGS) -fsyntax-only $(DSPIC_DIR)/main_dspic.c
	$(CC) $(DSPIC_CHECK_CFLAGS) -DPFW_HOST_CHECK -fsyntax-only $(DSPIC_DIR)/config_dspic.c
	$(CC) $(DSPIC_CHECK_CFLAGS) -o $@ $(DSPIC_DIR)/check/check_dspic.c $(DSPIC_DIR)/hal_dspic.c \
	  ports/common/boot_id.c $(CORE_SRC) -lm

dspic-check: $(DSPIC_BUILD)/check_dspic
	$(DSPIC_BUILD)/check_dspic
