/* The C interface used from C (C99): the header compiles as C and the library links from C.
 * Prints {"bad_address": STATUS, "reason": ..., "good_address": STATUS, "hfov_deg": ...,
 * "protocol": cd_protocol(), "header_protocol": CD_PROTOCOL}. */
#include <stdio.h>

#include "camdirector/camdirector.h"

int main(void) {
  char reason[256];
  cd_config config;
  cd_client* client = NULL;
  cd_status bad, good;
  cd_config_init(&config);
  config.address = "no-port";
  bad = cd_client_create(&config, &client);
  cd_check_address(config.address, reason, sizeof reason);
  config.address = "127.0.0.1:1";
  good = cd_client_create(&config, &client);
  cd_client_destroy(client);
  printf("{\"bad_address\": \"%s\", \"reason\": \"%s\", \"good_address\": \"%s\", \"hfov_deg\": %.17g, "
         "\"protocol\": %u, \"header_protocol\": %d}\n",
         cd_status_name(bad), reason, cd_status_name(good), cd_horizontal_fov_deg(50.0, 16.0 / 9.0),
         (unsigned)cd_protocol(), CD_PROTOCOL);
  return 0;
}
