; rob6.as -- rob6's AS program for a Kawasaki FS03N (E/F controller with the TCP/IP option),
; the server side of deploy/kawasaki/PROTOCOL.md (rob6-kas 2). Every construct it uses and
; its source: deploy/kawasaki/REFERENCES.md. Tested against controllers/kawasaki_as, which
; executes this file; NOT yet on a real controller: read deploy/kawasaki/README.md first.
;
;   rob6_pc     PC program 1 (PCEXECUTE 1: rob6_pc): sets the globals, starts rob6_state,
;               serves one rob6 driver on TCP port kport: checks each line, queues its
;               point, answers every line.
;   rob6_state  PC program 2: the state line every 50 ms while a driver is connected.
;   rob6_motion robot program (EXECUTE rob6_motion): JMOVEs the queued points.
;
; Shared globals, each written by one program only (kflush, kend, kmore: see below): the
; queue ring kq1[]..kq6[] (joints, deg), kms[] (ms), kfin[] (final 0/1), kseq[] of kcap
; points; kin points written and kgo points released to the motion (rob6_pc), kout points
; taken (rob6_motion), kflush the points dropped by a cancel or a stop; ksock the driver's
; socket (-1 none); kdone, kunder, ke[], kend and kmore (1: it streams, a point is due)
; what rob6_motion did. Everything else is local (.name) to one program; no name is
; longer than 15 characters.

.PROGRAM rob6_pc()
  kcap = 64
  kport = 49200
  kstart = 3
  kin = 0
  kgo = 0
  kout = 0
  kmore = 0
  kflush = 0
  kdone = 0
  kunder = 0
  kend = 0
  ksock = -1
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
  ; every slot defined: rob6_motion reads one before its point is there (and then ignores it)
  FOR .w = 0 TO kcap - 1
    kq1[.w] = 0
    kq2[.w] = 0
    kq3[.w] = 0
    kq4[.w] = 0
    kq5[.w] = 0
    kq6[.w] = 0
    kms[.w] = 1
    kfin[.w] = 0
    kseq[.w] = 0
  END
  PCEXECUTE 2: rob6_state
  TCP_LISTEN .ret, kport
  IF .ret < 0 THEN
    PRINT "rob6_pc: TCP_LISTEN on port ", kport, " failed: ", .ret
    HALT
  END
10
  TCP_ACCEPT .sock, kport, 60, .ip[1]
  IF .sock < 0 GOTO 10
  .last = 0
  .$buf = ""
  .$out[1] = "H rob6-kas 2 " + $ENCODE(/L, kcap) + $CHR(10)
  TCP_SEND .ret, .sock, .$out[1], 1, 1
  IF .ret < 0 GOTO 90
  ksock = .sock
20
  TCP_RECV .ret, .sock, .$in[1], .n, 1, 120
  IF .ret == -34024 GOTO 20
  IF .ret < 0 GOTO 90
  IF .n == 0 GOTO 90
  .i = 1
25
  .$buf = .$buf + .$in[.i]
30
  .p = INSTR(1, .$buf, $CHR(10))
  IF .p == 0 THEN
    IF LEN(.$buf) > 120 GOTO 90
    .i = .i + 1
    IF .i <= .n GOTO 25
    GOTO 20
  END
  .$line = $MID(.$buf, 1, .p - 1)
  .$buf = $MID(.$buf, .p + 1, 255)
  CALL rob6_line(.$line, .last, .seq, .code)
  .$out[1] = "A " + $ENCODE(/L, .seq, " ", /L, .code, " ", /L, kin - MAXVAL(kout, kflush)) + $CHR(10)
  TCP_SEND .ret, .sock, .$out[1], 1, 1
  IF .ret < 0 GOTO 90
  GOTO 30
90
  ; the driver is gone (closed, failed, or not rob6): drop the queue, the motion under way runs out
  ksock = -1
  kflush = kin
  TCP_CLOSE .ret, .sock
  GOTO 10
.END

.PROGRAM rob6_line(.$line, .last, .seq, .code)
  ; one line -> .seq (its sequence number, 0 when unreadable) and .code (the answer)
  .seq = 0
  .code = 1
  IF LEN(.$line) > 0 THEN
    IF $MID(.$line, LEN(.$line), 1) == $CHR(13) THEN
      .$line = $MID(.$line, 1, LEN(.$line) - 1)
    END
  END
  IF LEN(.$line) > 119 THEN
    RETURN
  END
  .nf = 0
10
  .$w = $DECODE(.$line, " ", 0)
  .$s = $DECODE(.$line, " ", 1)
  IF .$w <> "" THEN
    IF .nf == 10 THEN
      RETURN
    END
    .nf = .nf + 1
    .$f[.nf] = .$w
  END
  IF .$line <> "" GOTO 10
  IF .nf < 2 THEN
    RETURN
  END
  CALL rob6_num(.$f[2], .v, .kind)
  IF (.kind <> 1) OR (.v < 1) OR (.v > 999999) THEN
    RETURN
  END
  .seq = .v
  IF .$f[1] == "C" THEN
    IF .nf <> 2 THEN
      RETURN
    END
  ELSE
    IF (.$f[1] <> "P") OR (.nf <> 10) THEN
      RETURN
    END
    FOR .j = 1 TO 6
      CALL rob6_num(.$f[.j + 2], .v, .kind)
      IF .kind == 0 THEN
        RETURN
      END
      .q[.j] = .v
    END
    CALL rob6_num(.$f[9], .ms, .kind)
    IF (.kind <> 1) OR (.ms < 1) OR (.ms > 99999) THEN
      RETURN
    END
    IF (.$f[10] <> "0") AND (.$f[10] <> "1") THEN
      RETURN
    END
    .final = VAL(.$f[10])
  END
  IF .seq <= .last THEN
    .code = 6
    RETURN
  END
  .last = .seq
  IF .$f[1] == "C" THEN
    kflush = kin
    .code = 0
    RETURN
  END
  IF (NOT SWITCH(POWER)) OR (NOT SWITCH(REPEAT)) OR (ERROR <> 0) THEN
    .code = 4
    RETURN
  END
  ; where the point starts: the last point queued, else the last one JMOVEd, else the arm
  IF kin > MAXVAL(kout, kflush) THEN
    .w = (kin - 1) MOD kcap
    .from[1] = kq1[.w]
    .from[2] = kq2[.w]
    .from[3] = kq3[.w]
    .from[4] = kq4[.w]
    .from[5] = kq5[.w]
    .from[6] = kq6[.w]
  ELSE
    IF kend == 1 THEN
      FOR .j = 1 TO 6
        .from[.j] = ke[.j]
      END
    ELSE
      HERE .#here
      DECOMPOSE .from[1] = .#here
    END
  END
  FOR .j = 1 TO 6
    IF (.q[.j] < kmin[.j]) OR (.q[.j] > kmax[.j]) THEN
      .code = 2
      RETURN
    END
    IF ABS(.q[.j] - .from[.j]) * 1000 / .ms > krated[.j] * 1.05 THEN
      .code = 3
      RETURN
    END
  END
  IF kin - MAXVAL(kout, kflush) >= kcap THEN
    .code = 5
    RETURN
  END
  .w = kin MOD kcap
  kq1[.w] = .q[1]
  kq2[.w] = .q[2]
  kq3[.w] = .q[3]
  kq4[.w] = .q[4]
  kq5[.w] = .q[5]
  kq6[.w] = .q[6]
  kms[.w] = .ms
  kfin[.w] = .final
  kseq[.w] = .seq
  kin = kin + 1
  ; released to the motion at once while it streams; from rest once kstart points or a final one wait
  IF kmore == 1 THEN
    kgo = kin
  ELSE
    IF (kin - MAXVAL(kgo, kout, kflush) >= kstart) OR (.final == 1) THEN
      kgo = kin
    END
  END
  .code = 0
.END

.PROGRAM rob6_num(.$t, .v, .kind)
  ; .$t -> .kind 1 (an unsigned integer), 2 (another plain decimal number) or 0 (not a number), .v its value
  .kind = 0
  .v = 0
  .start = 1
  IF $MID(.$t, 1, 1) == "-" THEN
    .start = 2
  END
  .digits = 0
  .dots = 0
  FOR .k = .start TO LEN(.$t)
    .$c = $MID(.$t, .k, 1)
    IF .$c == "." THEN
      .dots = .dots + 1
    ELSE
      IF INSTR(1, "0123456789", .$c) == 0 THEN
        RETURN
      END
      .digits = .digits + 1
    END
  END
  IF (.digits == 0) OR (.dots > 1) OR (LEN(.$t) > 12) THEN
    RETURN
  END
  .v = VAL(.$t)
  .kind = 2
  IF (.start == 1) AND (.dots == 0) THEN
    .kind = 1
  END
.END

.PROGRAM rob6_state()
  ; every 50 ms: a stop drops the queue and the last target (the arm braked short of it);
  ; while a driver is connected, the state line
  .n = 0
  HERE .#was
  DECOMPOSE .was[1] = .#was
10
  .power = 0
  IF SWITCH(POWER) THEN
    .power = 1
  END
  .teach = 1
  IF SWITCH(REPEAT) THEN
    .teach = 0
  END
  IF (.power == 0) OR (.teach == 1) OR (ERROR <> 0) THEN
    kflush = kin
    kend = 0
    kmore = 0
  END
  HERE .#now
  DECOMPOSE .j[1] = .#now
  .q = kin - MAXVAL(kout, kflush)
  .moving = 0
  IF .q > 0 THEN
    .moving = 1
  END
  FOR .k = 1 TO 6
    IF ABS(.j[.k] - .was[.k]) > 0.0005 THEN
      .moving = 1
    END
    .was[.k] = .j[.k]
  END
  IF ksock >= 0 THEN
    .n = (.n + 1) MOD 1000000
    .$s[1] = "S " + $ENCODE(/L, .n)
    FOR .k = 1 TO 6
      .$s[1] = .$s[1] + " " + $ENCODE(/F9.3, .j[.k])
    END
    .$s[1] = .$s[1] + $ENCODE(" ", /L, .power, " ", /L, .teach, " ", /L, .moving, " ", /L, .q)
    .$s[1] = .$s[1] + $ENCODE(" ", /L, kdone, " ", /L, ERROR, " ", /L, kunder) + $CHR(10)
    TCP_SEND .ret, ksock, .$s[1], 1, 1
  END
  TWAIT 0.05
  GOTO 10
.END

.PROGRAM rob6_motion()
  ; one JMOVE a pass: the next released point, else (an idle pass) the last target again for
  ; 8 ms. A pass has no branch, loop or wait: a controller that meets one between two motion
  ; instructions plans no motion ahead across it and stops the arm at every point (motion
  ; type 1, REFERENCES.md), so every choice below is arithmetic (.has 1 a point, 0 none).
  ; A JMOVE waits until the motion before it has begun: the program runs one point ahead.
  ; CP is a switch the cell keeps: set here, as the accuracy, never assumed.
  CP ON
  ACCURACY 50 ALWAYS
  kout = MAXVAL(kin, kflush)
  kend = 0
  kmore = 0
  .fl = kflush
  HERE .#here
  DECOMPOSE ke[1] = .#here
10
  kout = MAXVAL(kout, kflush)
  .has = MAXVAL(0, -MAXVAL(kout - kgo, -1))
  .cut = MAXVAL(0, -MAXVAL(.fl - kflush, -1))
  .fl = kflush
  .r = kout MOD kcap
  .fin = .has * kfin[.r]
  ke[1] = ke[1] + .has * (kq1[.r] - ke[1])
  ke[2] = ke[2] + .has * (kq2[.r] - ke[2])
  ke[3] = ke[3] + .has * (kq3[.r] - ke[3])
  ke[4] = ke[4] + .has * (kq4[.r] - ke[4])
  ke[5] = ke[5] + .has * (kq5[.r] - ke[5])
  ke[6] = ke[6] + .has * (kq6[.r] - ke[6])
  kdone = kdone + .has * (kseq[.r] - kdone)
  ; a point due (the last one was not final) and none there: the arm stops, an underrun
  kunder = (kunder + (1 - .has) * kmore * (1 - .cut)) MOD 1000000
  kmore = .has * (1 - .fin)
  kend = MAXVAL(kend, .has)
  kout = kout + .has
  ; the final point exact (1 mm, then only idle passes to it), the others blended
  ACCURACY 50 - 49 * .fin
  SPEED (.has * kms[.r] + (1 - .has) * 8) / 1000 S
  JMOVE #PPOINT(ke[1], ke[2], ke[3], ke[4], ke[5], ke[6])
  GOTO 10
.END
