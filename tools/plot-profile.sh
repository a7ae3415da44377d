#!/usr/bin/env bash
# Plots of one `pushstep profile` folder, with gnuplot (Debian gnuplot-nox):
#   DIR/wakeup.png  wake-up latency histogram (1-us buckets, log count) from
#                   DIR/wakeup.hist (cyclictest -h text; a cyclictest output
#                   file works too: tools/plot-profile.sh --hist FILE OUT.png)
#   DIR/stages.png  p50 / p99 / p99.9 / max of every stage from DIR/profile.json
# Called by `pushstep profile` after it wrote DIR; needs only bash, awk, sed and
# gnuplot (no python: it runs from pushstep). Usage: tools/plot-profile.sh DIR
set -euo pipefail

die() {
    echo "plot-profile: $*" >&2
    exit 1
}
command -v gnuplot >/dev/null || die "gnuplot not installed (apt-get install gnuplot-nox)"

# Histogram file -> PNG. Title $3. The x range ends past the largest
# non-empty bucket (a few outliers far right would squash the body; the max,
# also when it overflowed the table, is printed in the title).
plot_hist() {
    local hist=$1 png=$2 title=$3
    local last max overflows
    last=$(awk '!/^#/ && NF >= 2 && $2 + 0 > 0 { l = $1 + 0 } END { print l + 0 }' "$hist")
    max=$(awk -F: '/^# Max Latencies/ { gsub(/ /, "", $2); print $2 + 0 }' "$hist")
    overflows=$(awk -F: '/^# Histogram Overflows/ { gsub(/ /, "", $2); print $2 + 0 }' "$hist")
    if ! awk '!/^#/ && NF >= 2 && $2 + 0 > 0 { found = 1 } END { exit !found }' "$hist"; then
        # Every sample beyond the table (or none at all): nothing to draw as
        # boxes, so say so on the picture instead of failing.
        gnuplot <<EOF
set terminal pngcairo size 1000,560 noenhanced font ",10"
set output "$png"
set title "$title  (max ${max:-?} us, overflows ${overflows:-0})"
unset key
set xrange [0:1]
set yrange [0:1]
set label "no sample inside the histogram (overflows ${overflows:-0}); see profile.json" at 0.5,0.5 center
plot 2 notitle
EOF
        return
    fi
    gnuplot <<EOF
set terminal pngcairo size 1000,560 noenhanced font ",10"
set output "$png"
set title "$title  (max ${max:-?} us, overflows ${overflows:-0})"
set xlabel "wake-up latency (us, 1-us buckets)"
set ylabel "samples"
set logscale y
set yrange [0.8:*]
set xrange [0:$((last + 2))]
set grid
set style fill solid 0.6 noborder
set boxwidth 1
plot "$hist" using (\$1+0.5):(\$2 > 0 ? \$2 : 1/0) with boxes lc rgb "#2060c0" notitle
EOF
}

# profile.json -> "stage p50 p99 p999 max" rows, in the file's order. cJSON
# pretty-prints one key per line; splitting at braces and commas first makes
# this work on compact JSON too. Tracks nesting: latency.<stage>.<field>.
stage_table() {
    sed -e 's/[{}]/\n&\n/g' -e 's/,/\n/g' "$1" | awk '
        { gsub(/[ \t\r]/, "") }
        $0 == "" { next }
        /^"[^"]*":$/ { pending = substr($0, 2, length($0) - 3); next }
        $0 == "{" { depth++; key[depth] = pending; pending = ""; next }
        $0 == "}" {
            if (depth == 3 && key[2] == "latency" && (key[3] in n))
                printf "%s %s %s %s %s\n", key[3], v[key[3], "p50_us"], v[key[3], "p99_us"],
                       v[key[3], "p999_us"], v[key[3], "max_us"]
            depth--; next
        }
        depth == 3 && key[2] == "latency" && /^"[a-z0-9_]+":/ {
            i = index($0, ":"); k = substr($0, 2, i - 3); val = substr($0, i + 1)
            v[key[3], k] = val; if (k == "n" && val + 0 > 0) n[key[3]] = 1
        }'
}

plot_stages() {
    local json=$1 png=$2 dat
    dat=$(mktemp)
    stage_table "$json" >"$dat"
    [ -s "$dat" ] || { rm -f "$dat"; die "no latency stages in $json"; }
    local period extra="" ymax="*"
    period=$(sed -n 's/.*"period_us":[[:space:]]*\([0-9.]*\).*/\1/p' "$json" | head -1)
    if [ -n "$period" ]; then
        extra=", $period with lines dt 2 lc rgb 'red' title 'period'"
        # room for the period line and for every bar, the largest max included
        ymax=$(awk -v p="$period" 'BEGIN { m = 3 * p } $5 * 2 > m { m = $5 * 2 } END { print m }' "$dat")
    fi
    gnuplot <<EOF
set terminal pngcairo size 1000,560 noenhanced font ",10"
set output "$png"
set title "pushstep stages: p50 / p99 / p99.9 / max (us, log scale)${period:+; period $period us}"
set ylabel "us"
set logscale y
set yrange [0.1:$ymax]
set grid ytics
set style data histogram
set style histogram clustered gap 1
set style fill solid 0.8 noborder
set xtics rotate by -30
set key top left
plot "$dat" using 2:xtic(1) title "p50", "" using 3 title "p99", "" using 4 title "p99.9", \
     "" using 5 title "max"$extra
EOF
    rm -f "$dat"
}

if [ "${1:-}" = "--hist" ]; then
    [ $# -ge 3 ] || die "usage: $0 --hist FILE OUT.png [TITLE]"
    plot_hist "$2" "$3" "${4:-$(basename "$2")}"
    exit 0
fi
[ $# -eq 1 ] && [ -d "$1" ] || die "usage: $0 DIR (a pushstep profile --out folder)"
dir=$1
[ -f "$dir/wakeup.hist" ] || die "$dir/wakeup.hist missing"
[ -f "$dir/profile.json" ] || die "$dir/profile.json missing"
plot_hist "$dir/wakeup.hist" "$dir/wakeup.png" "pushstep wake-up latency ($dir)"
plot_stages "$dir/profile.json" "$dir/stages.png"
echo "plot-profile: wrote $dir/wakeup.png $dir/stages.png"
