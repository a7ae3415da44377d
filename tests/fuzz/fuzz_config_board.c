/* libFuzzer target: board files (rt/ps_config_board.c, boards/ *.yaml) through
 * ps_config_load_board (tests/fuzz/fuzz_config.h). A loaded board has at
 * most PS_MAX_BUSES buses, each with a bit rate and a valid interface name,
 * and a bus budget in (0, 1]. */
#include "../../rt/ps_config.h"
#include "fuzz_config.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static ps_board_cfg_t b;
    char path[64], err[FUZZ_CONFIG_ERR_LEN];
    const int fd = fuzz_memfd(data, size, path, sizeof path);
    if (fd < 0)
        return 0;
    const int rc = ps_config_load_board(path, &b, err, sizeof err);
    close(fd);
    fuzz_config_check_err(rc, path, err);
    if (rc == 0) {
        FUZZ_CHECK(b.n_buses <= PS_MAX_BUSES, "n_buses %u", b.n_buses);
        FUZZ_CHECK(b.bus_budget > 0.0f && b.bus_budget <= 1.0f, "bus_budget %g", b.bus_budget);
        for (uint32_t i = 0; i < b.n_buses; i++) {
            FUZZ_CHECK(b.buses[i].bitrate > 0 && b.buses[i].data_bitrate > 0,
                       "bus %u bit rates %u/%u", i, b.buses[i].bitrate, b.buses[i].data_bitrate);
            FUZZ_CHECK(memchr(b.buses[i].ifname, '\0', sizeof b.buses[i].ifname) != NULL &&
                           b.buses[i].ifname[0] != '\0',
                       "bus %u without a name", i);
        }
    }
    return 0;
}
