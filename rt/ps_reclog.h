/*
 * ps_reclog: `pushstep log FILE.mcap`, reading a flight-recorder file back
 * (rt/ps_mcap.h reader, rt/ps_rosmsg.h decoder driven by the file's own
 * schemas, so it reads any flat ros2msg/CDR MCAP file):
 *
 *  - a summary: whether the file was closed or cut (and where reading
 *    stopped), duration, channels with message counts and schemas, the run's
 *    and the recorder's metadata (records lost), events (transitions,
 *    triggers), the fault conditions seen (first time, ticks), latency per
 *    stage from /timing (p50 / p99 / max);
 *  - --csv OUT.csv: chosen channels (--channels) or signals (--signals) as
 *    columns, one row per log time, a channel that has no message at that
 *    time repeating its last value;
 *  - --plot OUT.png: chosen signals over time, drawn by gnuplot (Debian
 *    gnuplot-nox); --signals balance is CoM, capture point and support
 *    polygon along x and y with the push force.
 *
 * A signal is CHANNEL.FIELD (every element of an array), CHANNEL.FIELD[i],
 * or, for fields by joint, CHANNEL.FIELD.JOINT (joint names from the file's
 * pushstep.run metadata); the channel's leading / may be left out.
 *
 * Threads: main. Allocation: NON-RT (a command of its own).
 */
#ifndef PS_RECLOG_H
#define PS_RECLOG_H

/** `pushstep log` (argv[0] = "log").  @return exit status: 0, 1 (the file
 *  cannot be read, a plot failed), 2 (usage)  @rt NON-RT */
int ps_reclog_main(int argc, char **argv);

#endif /* PS_RECLOG_H */
