/* `bounce trace`: not implemented yet (placeholder until its issue lands). */
#include "cli/cli.h"

int bn_cmd_trace(int argc, char **argv, bn_cli_common *c)
{
    (void)argc;
    (void)argv;
    (void)c;
    fprintf(stderr, "bounce: error: 'trace' is not implemented yet\n");
    return 1;
}
