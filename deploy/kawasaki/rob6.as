; rob6.as -- rob6's AS program pair for a Kawasaki FS03N (E/F controller with the TCP/IP option).
; Written from the AS language reference for deploy/kawasaki/PROTOCOL.md (rob6-kas 1).
; Tested against rob6's simulator (controllers/kawasaki_as), NOT yet on a real controller:
; read deploy/kawasaki/README.md before loading it.
;
;   rob6_pc     PC program (PCEXECUTE 1: rob6_pc): serves one rob6 driver on TCP port
;               kport, parses point lines into the queue, answers every line.
;   rob6_state  PC program (PCEXECUTE 2: rob6_state): sends the state line every 50 ms
;               while a driver is connected.
;   rob6_motion robot program (EXECUTE rob6_motion): executes the queue with JMOVE #PPOINT,
;               blending (CP ON, coarse ACCURACY) all but the final point of a motion.
;
; The queue lives in global variables: one ring of kcap points (kq1[]..kq6[] joints in
; degrees, kms[] time in ms, kfin[] final flag, kseq[] sequence number). rob6_pc only
; writes kin (points written), rob6_motion only writes kout (points taken); a cancel
; sets kflush, from which rob6_motion drops the points not yet taken.

.PROGRAM rob6_init()
  ; the globals both sides use; run once before the others (the PC program calls it)
  kcap = 64
  kport = 49200
  kacc = 50            ; ACCURACY (mm) of blended points: large, so CP blends them
  kstart = 3           ; a motion starts at this many points (or a final one): two periods of lead
  kin = 0
  kout = 0
  kflush = 0
  kunder = 0
  kdone = 0
  ksock = -1
  kstates = 0
  ; rated axis speeds of the FS03N, deg/s, and the motion range (data sheet)
  krated[1] = 360
  krated[2] = 250
  krated[3] = 225
  krated[4] = 540
  krated[5] = 225
  krated[6] = 540
  kmin[1] = -160
  kmax[1] = 160
  kmin[2] = -60
  kmax[2] = 150
  kmin[3] = -150
  kmax[3] = 120
  kmin[4] = -360
  kmax[4] = 360
  kmin[5] = -135
  kmax[5] = 135
  kmin[6] = -360
  kmax[6] = 360
.END

.PROGRAM rob6_pc()
  ; serves one client; a second connection waits until the first is gone
  CALL rob6_init
  TCP_LISTEN ret, kport
  IF ret < 0 THEN
    PRINT "rob6_pc: TCP_LISTEN on port ", kport, " failed: ", ret
    HALT
  END
10
  TCP_ACCEPT ksock, kport, 60, kip[1]
  IF ksock < 0 THEN
    GOTO 10                       ; no client within 60 s (or an error): listen on
  END
  klast = 0
  $kbuf = ""
  $kout[1] = "H rob6-kas 1 " + $ENCODE(/I2, kcap) + $CHR(10)
  TCP_SEND ret, ksock, $kout[1], 1, 2
  IF ret < 0 THEN
    GOTO 90
  END
20
  TCP_RECV ret, ksock, $kin[1], kn, 1, 255
  IF ret < 0 THEN
    IF ret == -34 THEN            ; the receive timed out: nothing came, listen again
      GOTO 20
    END
    GOTO 90                       ; the client closed the connection or it failed
  END
  FOR ki = 1 TO kn
    $kbuf = $kbuf + $kin[ki]
  END
30
  kp = INSTR(1, $kbuf, $CHR(10))
  IF kp == 0 THEN
    IF LEN($kbuf) > 120 THEN      ; no line end within a message's length: not rob6
      GOTO 90
    END
    GOTO 20
  END
  $kline = $MID($kbuf, 1, kp - 1)
  $kbuf = $MID($kbuf, kp + 1, LEN($kbuf) - kp)
  CALL rob6_line
  $kout[1] = "A " + $ENCODE(/I6, kaseq) + " " + $ENCODE(/I1, kcode) + " " + $ENCODE(/I3, kin - kout) + $CHR(10)
  TCP_SEND ret, ksock, $kout[1], 1, 2
  IF ret < 0 THEN
    GOTO 90
  END
  GOTO 30
90
  ; the client is gone: drop the queue (the motion under way runs out) and wait for the next
  kflush = kin
  TCP_CLOSE ret, ksock
  ksock = -1
  GOTO 10
.END

.PROGRAM rob6_line()
  ; one line in $kline -> kaseq (its sequence number) and kcode (the answer code)
  kaseq = 0
  kcode = 1
  $kt = $DECODE($kline, " ", 0)
  $kd = $DECODE($kline, " ", 1)
  $ks = $DECODE($kline, " ", 0)
  $kd = $DECODE($kline, " ", 1)
  kaseq = VAL($ks)
  IF (kaseq < 1) OR (kaseq > 999999) THEN
    kaseq = 0
    RETURN
  END
  IF kaseq <= klast THEN
    kcode = 6
    RETURN
  END
  klast = kaseq
  IF $kt == "C" THEN
    kflush = kin                  ; rob6_motion drops what it has not taken
    kcode = 0
    RETURN
  END
  IF $kt <> "P" THEN
    RETURN
  END
  FOR kj = 1 TO 8
    $kf = $DECODE($kline, " ", 0)
    $kd = $DECODE($kline, " ", 1)
    IF $kf == "" THEN
      RETURN                      ; a field short
    END
    kv[kj] = VAL($kf)
  END
  $kf = $DECODE($kline, " ", 0)
  IF ($kf <> "0") AND ($kf <> "1") THEN
    RETURN
  END
  kfinal = VAL($kf)
  IF (kv[7] < 1) OR (kv[7] > 99999) THEN
    RETURN
  END
  ; ready? E-stop, motor power, repeat mode, no error
  IF SWITCH(EMERGENCY) OR NOT SWITCH(POWER) OR NOT SWITCH(REPEAT) OR (ERROR <> 0) THEN
    kcode = 4
    RETURN
  END
  ; range, and speed from the point before (the last queued, or where the arm is)
  IF kin > MAXVAL(kout, kflush) THEN
    kprev = (kin - 1) MOD kcap
    kfrom[1] = kq1[kprev]
    kfrom[2] = kq2[kprev]
    kfrom[3] = kq3[kprev]
    kfrom[4] = kq4[kprev]
    kfrom[5] = kq5[kprev]
    kfrom[6] = kq6[kprev]
  ELSE
    HERE #khere
    DECOMPOSE kfrom[1] = #khere
  END
  FOR kj = 1 TO 6
    IF (kv[kj] < kmin[kj]) OR (kv[kj] > kmax[kj]) THEN
      kcode = 2
      RETURN
    END
    IF ABS(kv[kj] - kfrom[kj]) * 1000 / kv[7] > krated[kj] * 1.05 THEN
      kcode = 3
      RETURN
    END
  END
  IF kin - MAXVAL(kout, kflush) >= kcap THEN
    kcode = 5
    RETURN
  END
  kw = kin MOD kcap
  kq1[kw] = kv[1]
  kq2[kw] = kv[2]
  kq3[kw] = kv[3]
  kq4[kw] = kv[4]
  kq5[kw] = kv[5]
  kq6[kw] = kv[6]
  kms[kw] = kv[7]
  kfin[kw] = kfinal
  kseq[kw] = kaseq
  kin = kin + 1                   ; last: rob6_motion sees the point only when it is complete
  kcode = 0
.END

.PROGRAM rob6_state()
  ; the state line every 50 ms while a client is connected
10
  IF ksock < 0 THEN
    TWAIT 0.05
    GOTO 10
  END
  IF SWITCH(EMERGENCY) OR NOT SWITCH(POWER) OR NOT SWITCH(REPEAT) OR (ERROR <> 0) THEN
    kflush = kin                  ; a stop drops the queue: nothing old runs after it
  END
  kq = kin - MAXVAL(kout, kflush)
  HERE #kst
  DECOMPOSE kj[1] = #kst
  kstates = (kstates + 1) MOD 1000000
  $kso[1] = "S " + $ENCODE(/I6, kstates)
  FOR kk = 1 TO 6
    $kso[1] = $kso[1] + " " + $ENCODE(/F9.3, kj[kk])
  END
  kmoving = (kq > 0)              ; points waiting, or a joint moved since the last state
  FOR kk = 1 TO 6
    IF ABS(kj[kk] - kjlast[kk]) > 0.0005 THEN
      kmoving = TRUE
    END
    kjlast[kk] = kj[kk]
  END
  $kso[1] = $kso[1] + " " + $ENCODE(/I1, SWITCH(POWER) AND 1) + " " + $ENCODE(/I1, SWITCH(EMERGENCY) AND 1)
  $kso[1] = $kso[1] + " " + $ENCODE(/I1, NOT SWITCH(REPEAT) AND 1) + " " + $ENCODE(/I1, kmoving AND 1)
  $kso[1] = $kso[1] + " " + $ENCODE(/I3, kq) + " " + $ENCODE(/I6, kdone) + " " + $ENCODE(/I5, ERROR)
  $kso[1] = $kso[1] + " " + $ENCODE(/I6, kunder) + $CHR(10)
  TCP_SEND ret, ksock, $kso[1], 1, 1
  TWAIT 0.05
  GOTO 10
.END

.PROGRAM rob6_motion()
  ; executes the queue: starts a motion at kstart points or a final one, blends all but the final
  kout = kin                      ; (re)started after a stop: points from before it never run
  ACCURACY kacc ALWAYS
10
  IF kflush > kout THEN
    kout = kflush                 ; cancelled (or the client went): drop what was not taken
  END
  IF (kin - kout >= kstart) OR ((kin > kout) AND (kfin[(kin - 1) MOD kcap] == 1)) THEN
    GOTO 20
  END
  TWAIT 0.008
  GOTO 10
20
  IF kflush > kout THEN
    kout = kflush
    BREAK                         ; the motion under way runs out; nothing more is issued
    GOTO 10
  END
  IF kin - kout < 1 THEN          ; ran dry before a final point: an underrun
    kunder = kunder + 1
    BREAK
    GOTO 10
  END
  kr = kout MOD kcap
  SPEED kms[kr] / 1000 S
  IF kfin[kr] == 1 THEN
    ACCURACY 1 FINE
    CP OFF
  ELSE
    ACCURACY kacc
    CP ON
  END
  JMOVE #PPOINT(kq1[kr], kq2[kr], kq3[kr], kq4[kr], kq5[kr], kq6[kr])
  kdone = kseq[kr]
  kout = kout + 1
  IF kfin[kr] == 1 THEN
    BREAK                         ; wait until the arm is at the final point
    GOTO 10
  END
  GOTO 20
.END
