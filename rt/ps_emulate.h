/*
 * ps_emulate: `pushstep emulate`, the robot on a hoist (sim/ps_hoist) at the
 * far end of real CAN interfaces, for running the real drivers with no robot:
 * in the test VM the runtime drives vxcan0 and the emulator answers on its
 * peer vxcan1. It is also the bench instrument of those runs: it timestamps
 * every frame (kernel receive stamps) and reports
 *  - reaction: from each reply it sent to the next command of that drive
 *    (what the runtime's loop took from reply in to command out, plus the
 *    wait for its next tick), as percentiles;
 *  - command rate per bus and late commands (a drive's command more than
 *    half a period after its rate_div grid said);
 *  - e-stop: with --estop-file and --press-estop-at it presses the e-stop
 *    (writes the line's pull in gpio-mockup's debugfs) and reports the time
 *    to the first command with kp = 0 or the first disable, in ms and ticks;
 *  - with --heartbeat-file it plays the watchdog relay: the drives are
 *    powered only while the enable line changed within
 *    PS_GPIO_HEARTBEAT_TIMEOUT_NS, and it reports when the heartbeat stopped.
 *
 * Threads: main thread. Allocation: at start-up only.
 */
#ifndef PS_EMULATE_H
#define PS_EMULATE_H

/** Parse argv (argv[0] = "emulate"), run, print the report.
 *  @return process exit status: 0 ok, 1 runtime failure, 2 usage/config  @rt INIT */
int ps_emulate_main(int argc, char **argv, const char *data_dir);

#endif /* PS_EMULATE_H */
