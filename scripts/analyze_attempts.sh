#!/bin/bash
# Acceptance-threshold check on the attempts.csv of `geodrift run --geotags`: for attempts on
# frames > F (default 150, outside the stretch the thresholds were chosen on) with a PnP estimate,
# the distance between the view position (through the corrected keyframe) and its geo-tag,
# by inlier count and by tilt. Usage: scripts/analyze_attempts.sh RUN/attempts.csv [F]
set -euo pipefail
A=${1:?usage: analyze_attempts.sh RUN/attempts.csv [min_frame]}; F=${2:-150}
[ -r "$A" ] || { echo "analyze_attempts.sh: cannot read $A" >&2; exit 1; }
# The columns used below, by position; refuse a file of another layout.
expect="keyframe,frame,view,geotag,score,putative,kvld_kept,pairs_3d,inliers,rms_px,tilt_deg,accepted,x,y,z,dx_m,reason"
[ "$(sed -n 2p "$A")" = "$expect" ] || { echo "analyze_attempts.sh: $A: line 2 is not the attempts.csv header ($expect)" >&2; exit 1; }
awk -F, -v F=$F 'NR>2 && $2>F && $16!="" {
  n++; inl=$9; tilt=$11; acc=$12; dx=$16; bad=(dx>2.0);
  if(acc==1){na++; if(bad)nab++; if(dx>mx)mx=dx; s+=dx}
  if(acc==0 && $17 ~ /inliers/ && inl>=25 && inl<40){nr++; if(bad)nrb++; sr+=dx}
  if(acc==0 && $17 ~ /tilted/){nt++; if(bad)ntb++}
  if(inl>=40 && tilt!="" && tilt<=10 && acc==0) other++;
} END {
  printf "attempts with a PnP estimate (frames > %d): %d\n", F, n;
  printf "accepted: %d, of which > 2 m from the geo-tag: %d, mean %.2f m, max %.2f m\n", na, nab, (na?s/na:0), mx;
  printf "rejected by the inlier threshold with 25-39 inliers: %d, of which > 2 m: %d, mean %.2f m\n", nr, nrb, (nr?sr/nr:0);
  printf "rejected by the 10 deg tilt check: %d, of which > 2 m: %d\n", nt, ntb;
  printf ">=40 inliers, tilt<=10, rejected by other tests: %d\n", other;
}' $A
echo "inlier-count bins (frames > $F, estimate present): inliers range, n, n > 2 m, median dx"
awk -F, -v F=$F 'NR>2 && $2>F && $16!="" {b=($9<20?"00-19":($9<30?"20-29":($9<40?"30-39":($9<60?"40-59":"60+")))); print b, $16, $11, $12}' $A | sort -k1,1 -k2,2g | awk '{k=$1; c[k]++; if($2>2)bad[k]++; v[k,c[k]]=$2} END{for(k in c){printf "  %s  n=%d  >2m=%d  median=%.2f\n",k,c[k],bad[k]+0,v[k,int((c[k]+1)/2)]}}' | sort
echo "tilt bins of attempts with >= 40 inliers: tilt, n, n > 2 m"
awk -F, -v F=$F 'NR>2 && $2>F && $16!="" && $9>=40 && $11!="" {b=($11<2?"0-2":($11<5?"2-5":($11<10?"5-10":"10+"))); c[b]++; if($16>2)bad[b]++} END{for(k in c)printf "  %s deg  n=%d  >2m=%d\n",k,c[k],bad[k]+0}' $A | sort
