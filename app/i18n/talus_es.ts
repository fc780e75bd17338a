<?xml version='1.0' encoding='utf-8'?>
<TS version="2.1" language="es_ES">
<context>
    <name />
    <message>
        <location filename="../field_labels.py" line="19" />
        <source>Name</source>
        <extracomment>Unit suffixes of field names → the unit shown.</extracomment>
        <translation>Nombre</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="19" />
        <source>Description</source>
        <translation>Descripción</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="20" />
        <source>Platform position</source>
        <translation>Posición de la plataforma</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="20" />
        <source>Height (m)</source>
        <translation>Altura (m)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="23" />
        <source>Mean force (N)</source>
        <translation>Fuerza media (N)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="23" />
        <source>Force amplitude (N)</source>
        <translation>Amplitud de fuerza (N)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="24" />
        <source>Frequency (Hz)</source>
        <translation>Frecuencia (Hz)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="24" />
        <source>Cycles</source>
        <translation>Ciclos</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="25" />
        <source>Ramp in (s)</source>
        <translation>Rampa de entrada (s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="25" />
        <source>Ramp out (s)</source>
        <translation>Rampa de salida (s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="26" />
        <source>Ramp (s)</source>
        <translation>Rampa (s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="27" />
        <source>Limits of this protocol</source>
        <translation>Límites de este protocolo</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="21" />
        <source>Roll tilt (°)</source>
        <translation>Inclinación en balanceo (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="22" />
        <source>Pitch tilt (°)</source>
        <translation>Inclinación en cabeceo (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="28" />
        <source>Minimum roll (°)</source>
        <translation>Balanceo mínimo (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="29" />
        <source>Maximum roll (°)</source>
        <translation>Balanceo máximo (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="30" />
        <source>Minimum pitch (°, dorsiflexion)</source>
        <translation>Cabeceo mínimo (°, dorsiflexión)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="31" />
        <source>Maximum pitch (°, plantarflexion)</source>
        <translation>Cabeceo máximo (°, plantarflexión)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="32" />
        <location filename="../pages/patients.py" line="93" />
        <source>Maximum force (N)</source>
        <translation>Fuerza máxima (N)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="33" />
        <location filename="../pages/patients.py" line="94" />
        <source>Maximum angular speed (°/s)</source>
        <translation>Velocidad angular máxima (°/s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="34" />
        <source>Movements</source>
        <translation>Movimientos</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="34" />
        <source>Range per direction (°)</source>
        <translation>Rango por dirección (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="35" />
        <location filename="../pages/patients.py" line="90" />
        <source>Dorsiflexion (°)</source>
        <translation>Dorsiflexión (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="35" />
        <location filename="../pages/patients.py" line="91" />
        <source>Plantarflexion (°)</source>
        <translation>Plantarflexión (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="36" />
        <location filename="../pages/patients.py" line="92" />
        <source>Inversion (°)</source>
        <translation>Inversión (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="36" />
        <location filename="../pages/patients.py" line="92" />
        <source>Eversion (°)</source>
        <translation>Eversión (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="37" />
        <source>Speed (°/s)</source>
        <translation>Velocidad (°/s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="37" />
        <source>Repetitions</source>
        <translation>Repeticiones</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="38" />
        <source>Hold at each end (s)</source>
        <translation>Pausa en cada extremo (s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="38" />
        <source>Motion profile</source>
        <translation>Perfil de movimiento</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="39" />
        <source>Maximum acceleration (°/s²)</source>
        <translation>Aceleración máxima (°/s²)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="40" />
        <source>Maximum jerk (°/s³)</source>
        <translation>Sobreaceleración máxima (°/s³)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="41" />
        <source>Gait record file</source>
        <translation>Archivo de registro de marcha</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="41" />
        <source>Trajectory file</source>
        <translation>Archivo de trayectoria</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="42" />
        <source>Load (% body weight)</source>
        <translation>Carga (% del peso corporal)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="42" />
        <source>Time scale</source>
        <translation>Escala de tiempo</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="43" />
        <source>Force plate</source>
        <translation>Plataforma de fuerzas</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="43" />
        <source>Include shear forces</source>
        <translation>Incluir fuerzas tangenciales</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="44" />
        <source>Body mass in the record (kg)</source>
        <translation>Masa corporal en el registro (kg)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="45" />
        <source>Holds</source>
        <translation>Mantenimientos</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="45" />
        <source>Rest (s)</source>
        <translation>Descanso (s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="45" />
        <source>Rest between (s)</source>
        <translation>Descanso entre (s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="46" />
        <source>Target force (N)</source>
        <translation>Fuerza objetivo (N)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="46" />
        <source>Duration (s)</source>
        <translation>Duración (s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="47" />
        <source>Assistance gain</source>
        <translation>Ganancia de asistencia</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="47" />
        <source>Threshold (N)</source>
        <translation>Umbral (N)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="48" />
        <source>Guide period (s)</source>
        <translation>Periodo de guía (s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="48" />
        <source>Admittance</source>
        <translation>Admitancia</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="49" />
        <source>Stiffness (N·m/rad)</source>
        <translation>Rigidez (N·m/rad)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="50" />
        <source>Damping (N·m·s/rad)</source>
        <translation>Amortiguamiento (N·m·s/rad)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="51" />
        <source>Interpolation</source>
        <translation>Interpolación</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="51" />
        <source>Sample rate (Hz)</source>
        <translation>Frecuencia de muestreo (Hz)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="52" />
        <source>Stance</source>
        <translation>Apoyo</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="52" />
        <source>Transition speed (°/s)</source>
        <translation>Velocidad de transición (°/s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="53" />
        <source>Maximum speed (°/s)</source>
        <translation>Velocidad máxima (°/s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="53" />
        <source>Axes</source>
        <translation>Ejes</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="54" />
        <source>Range (°)</source>
        <translation>Rango (°)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="54" />
        <source>Start (s)</source>
        <translation>Inicio (s)</translation>
    </message>
    <message>
        <location filename="../field_labels.py" line="54" />
        <source>End (s)</source>
        <translation>Fin (s)</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="43" />
        <source>talus — rehabilitation robot</source>
        <extracomment>The clinic touchscreen (issue 14): everything fits without horizontal scrolling. The pages in rail order (screenshots are named after them); login and patients come with a clinical record.</extracomment>
        <translation>talus — robot de rehabilitación</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="67" />
        <location filename="../pages/login.py" line="35" />
        <source>Log in</source>
        <translation>Iniciar sesión</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="68" />
        <source>Patients</source>
        <translation>Pacientes</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="69" />
        <source>Prescribe</source>
        <translation>Prescribir</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="70" />
        <source>Run</source>
        <translation>Ejecutar</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="71" />
        <source>Review</source>
        <translation>Revisar</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="72" />
        <source>Settings</source>
        <translation>Ajustes</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="78" />
        <source>Log out</source>
        <translation>Cerrar sesión</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="80" />
        <source>Logged out.</source>
        <translation>Sesión cerrada.</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="96" />
        <source>Locked after %1 min without use.</source>
        <translation>Bloqueado tras %1 min sin uso.</translation>
    </message>
    <message>
        <location filename="../main_window.py" line="226" />
        <source>Reset refused: %1</source>
        <translation>Rearme rechazado: %1</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="66" />
        <source>Protocols</source>
        <translation>Protocolos</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="92" />
        <location filename="../pages/review.py" line="71" />
        <location filename="../pages/run.py" line="95" />
        <source>time (s)</source>
        <translation>tiempo (s)</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="96" />
        <location filename="../pages/prescribe.py" line="153" />
        <source>Pre-flight not run yet.</source>
        <translation>Comprobación previa aún no realizada.</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="100" />
        <source>Check on the robot model (pre-flight)</source>
        <translation>Comprobar en el modelo del robot (comprobación previa)</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="101" />
        <source>Start on the Run page</source>
        <translation>Iniciar en la página Ejecutar</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="154" />
        <source>Correct the fields marked in red first.</source>
        <translation>Corrija primero los campos marcados en rojo.</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="163" />
        <source>Computing the preview…</source>
        <translation>Calculando la vista previa…</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="180" />
        <source>No preview: %1</source>
        <translation>Sin vista previa: %1</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="183" />
        <source>This protocol cannot be played: %1</source>
        <translation>Este protocolo no se puede ejecutar: %1</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="187" />
        <source>force (N)</source>
        <translation>fuerza (N)</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="189" />
        <source>force reference</source>
        <translation>referencia de fuerza</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="191" />
        <source>angle (°)</source>
        <translation>ángulo (°)</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="193" />
        <location filename="../pages/review.py" line="135" />
        <location filename="../pages/run.py" line="104" />
        <source>plantar(+)/dorsi(−) flexion</source>
        <translation>flexión plantar(+)/dorsal(−)</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="195" />
        <location filename="../pages/review.py" line="137" />
        <source>roll (+ is inversion of a right foot)</source>
        <translation>balanceo (+ es inversión del pie derecho)</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="107" />
        <source>inversion(+)/eversion(−)</source>
        <translation>inversión(+)/eversión(−)</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="196" />
        <source>Duration: %1 s</source>
        <translation>Duración: %1 s</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="207" />
        <source>Pre-flight running on the robot model…</source>
        <translation>Comprobación previa en curso en el modelo del robot…</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="220" />
        <source>REFUSED: %1</source>
        <translation>RECHAZADO: %1</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="226" />
        <source>Pre-flight passed. Predicted peaks: %1</source>
        <translation>Comprobación previa superada. Picos previstos: %1</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="237" />
        <source>Choose a patient first</source>
        <translation>Elija primero un paciente</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="250" />
        <source>platform force %1 N</source>
        <translation>fuerza en la plataforma %1 N</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="252" />
        <source>dorsi/plantarflexion</source>
        <translation>dorsi/plantarflexión</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="252" />
        <source>inversion/eversion</source>
        <translation>inversión/eversión</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="258" />
        <source>force tracking error %1 %</source>
        <translation>error de seguimiento de fuerza %1 %</translation>
    </message>
    <message>
        <location filename="../pages/prescribe.py" line="261" />
        <source>duration %1 s</source>
        <translation>duración %1 s</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="57" />
        <source>Refresh</source>
        <translation>Actualizar</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="58" />
        <source>Open</source>
        <translation>Abrir</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="63" />
        <source>Choose a session on the left.</source>
        <translation>Elija una sesión a la izquierda.</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="65" />
        <location filename="../pages/run.py" line="85" />
        <source>Force (N)</source>
        <translation>Fuerza (N)</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="66" />
        <location filename="../pages/run.py" line="86" />
        <source>Ankle angles (°)</source>
        <translation>Ángulos del tobillo (°)</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="76" />
        <source>Recorded sessions</source>
        <translation>Sesiones grabadas</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="113" />
        <source>Reading %1…</source>
        <translation>Leyendo %1…</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="127" />
        <source>Cannot open: %1</source>
        <translation>No se puede abrir: %1</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="131" />
        <location filename="../pages/run.py" line="99" />
        <source>reference</source>
        <translation>referencia</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="133" />
        <location filename="../pages/run.py" line="101" />
        <source>measured</source>
        <translation>medida</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="146" />
        <source>%1 — patient %2 — %3 s</source>
        <translation>%1 — paciente %2 — %3 s</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="149" />
        <source>stops: %1</source>
        <translation>paradas: %1</translation>
    </message>
    <message>
        <location filename="../pages/review.py" line="152" />
        <source>recording cut short (recovered up to its last whole block)</source>
        <translation>grabación interrumpida (recuperada hasta su último bloque completo)</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="38" />
        <source>moving to the start position</source>
        <extracomment>Redraw rate of the live plots, Hz (the issue asks ≥ 30 fps). Seconds of history on the live plots.</extracomment>
        <translation>yendo a la posición inicial</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="38" />
        <source>exercise</source>
        <translation>ejercicio</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="39" />
        <source>returning to rest</source>
        <translation>volviendo al reposo</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="39" />
        <source>stopped</source>
        <translation>detenido</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="40" />
        <source>at rest</source>
        <translation>en reposo</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="72" />
        <source>No protocol prescribed: choose one in Prescribe.</source>
        <extracomment>False for roles that may not move the robot (viewer, engineer, admin) the clinical record's journal of sessions (None: no record)</extracomment>
        <translation>Ningún protocolo prescrito: elija uno en Prescribir.</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="74" />
        <source>Take control of the robot</source>
        <translation>Tomar el control del robot</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="75" />
        <source>Start session</source>
        <translation>Iniciar sesión</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="181" />
        <source>Protocol: %1</source>
        <translation>Protocolo: %1</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="196" />
        <source>Checking the protocol on the robot model, then starting…</source>
        <translation>Comprobando el protocolo en el modelo del robot; después se inicia…</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="209" />
        <source>Could not take control: %1</source>
        <translation>No se pudo tomar el control: %1</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="210" />
        <source>You control the robot.</source>
        <translation>Usted controla el robot.</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="214" />
        <source>The session did not start: %1</source>
        <translation>La sesión no se inició: %1</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="226" />
        <source>Session running.</source>
        <translation>Sesión en curso.</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="240" />
        <source>Session ended: %1</source>
        <translation>Sesión terminada: %1</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="244" />
        <source>Stopped: %1</source>
        <translation>Detenido: %1</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="249" />
        <source>The clinical record did not take the session: %1</source>
        <translation>La historia clínica no registró la sesión: %1</translation>
    </message>
    <message>
        <location filename="../pages/run.py" line="295" />
        <source>%1 s left</source>
        <translation>quedan %1 s</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="33" />
        <source>default: the local SQLite clinical record</source>
        <translation>por defecto: la historia clínica local SQLite</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="44" />
        <source>RT process endpoint</source>
        <translation>Dirección del proceso de tiempo real</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="45" />
        <source>Clinical record database URL</source>
        <translation>URL de la base de datos clínica</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="46" />
        <source>Recordings folder</source>
        <translation>Carpeta de grabaciones</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="47" />
        <source>Clinic name (reports)</source>
        <translation>Nombre de la clínica (informes)</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="48" />
        <source>Clinic logo file (reports)</source>
        <translation>Archivo del logotipo de la clínica (informes)</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="49" />
        <source>Language</source>
        <translation>Idioma</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="50" />
        <source>Lock the screen after idle (minutes)</source>
        <translation>Bloquear la pantalla tras inactividad (minutos)</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="51" />
        <source>RT reply timeout (s)</source>
        <translation>Tiempo de espera de respuesta TR (s)</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="55" />
        <source>Save</source>
        <translation>Guardar</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="72" />
        <source>Idle lock and timeout must be numbers.</source>
        <translation>El bloqueo por inactividad y el tiempo de espera deben ser números.</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="84" />
        <source>Not saved: %1</source>
        <translation>No guardado: %1</translation>
    </message>
    <message>
        <location filename="../pages/settings_page.py" line="90" />
        <source>Saved. A new endpoint or language applies when the GUI is started again.</source>
        <translation>Guardado. Una nueva dirección o idioma se aplica al volver a iniciar la interfaz.</translation>
    </message>
    <message>
        <location filename="../protocol_form.py" line="153" />
        <source>Parameters</source>
        <extracomment>Keys never edited in the form (they say what the document is). Source name in validation messages (stripped before display). the nearest optional block holding this field ("" when none): a block left wholly empty is omitted, so its required fields are only required once one of them is set</extracomment>
        <translation>Parámetros</translation>
    </message>
    <message>
        <location filename="../protocol_form.py" line="183" />
        <source>Edited in the protocol file</source>
        <translation>Se edita en el archivo del protocolo</translation>
    </message>
    <message>
        <location filename="../protocol_form.py" line="263" />
        <source>required</source>
        <translation>obligatorio</translation>
    </message>
    <message>
        <location filename="../protocol_form.py" line="270" />
        <source>a number is needed</source>
        <translation>se necesita un número</translation>
    </message>
    <message>
        <location filename="../protocol_form.py" line="271" />
        <source>a whole number is needed</source>
        <translation>se necesita un número entero</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="44" />
        <source>Reset…</source>
        <translation>Rearmar…</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="49" />
        <source>Patient checked: clear</source>
        <translation>Paciente revisado: borrar</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="50" />
        <source>Cancel</source>
        <translation>Cancelar</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="75" />
        <source>not connected yet</source>
        <translation>aún sin conexión</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="80" />
        <source>Patient: %1</source>
        <translation>Paciente: %1</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="81" />
        <source>No patient selected</source>
        <translation>Ningún paciente seleccionado</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="96" />
        <source>Robot connected</source>
        <translation>Robot conectado</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="98" />
        <source>Robot NOT connected: %1</source>
        <translation>Robot NO conectado: %1</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="100" />
        <source>Controlled by: %1</source>
        <translation>Controlado por: %1</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="101" />
        <source>Nobody controls the robot</source>
        <translation>Nadie controla el robot</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="104" />
        <source>Why: %1</source>
        <translation>Motivo: %1</translation>
    </message>
    <message>
        <location filename="../status_band.py" line="125" />
        <source>Reset will clear:</source>
        <translation>El rearme borrará:</translation>
    </message>
    <message>
        <location filename="../stop_panel.py" line="43" />
        <source>STOP</source>
        <extracomment>Keys: Esc for STOP (the key a hand finds without looking), F12 for E-STOP. GUI.md: STOP at least 120 px wide.</extracomment>
        <translation>PARAR</translation>
    </message>
    <message>
        <location filename="../stop_panel.py" line="45" />
        <source>E-STOP</source>
        <translation>EMERGENCIA</translation>
    </message>
    <message>
        <location filename="../words.py" line="23" />
        <source>Idle — robot at rest</source>
        <extracomment>Colours of the robot states (GUI.md: grey idle, green running, amber soft stop, red hard).</extracomment>
        <translation>Inactivo — robot en reposo</translation>
    </message>
    <message>
        <location filename="../words.py" line="24" />
        <source>Running</source>
        <translation>En marcha</translation>
    </message>
    <message>
        <location filename="../words.py" line="25" />
        <source>Stopped (soft stop) — reset to continue</source>
        <translation>Detenido (parada suave) — rearme para continuar</translation>
    </message>
    <message>
        <location filename="../words.py" line="26" />
        <source>EMERGENCY STOP — drives off</source>
        <translation>PARADA DE EMERGENCIA — motores desactivados</translation>
    </message>
    <message>
        <location filename="../words.py" line="27" />
        <source>Connection to the robot lost — motion disabled</source>
        <translation>Conexión con el robot perdida — movimiento desactivado</translation>
    </message>
    <message>
        <location filename="../words.py" line="46" />
        <source>E-STOP pressed on this screen</source>
        <translation>PARADA DE EMERGENCIA pulsada en esta pantalla</translation>
    </message>
    <message>
        <location filename="../words.py" line="47" />
        <source>E-STOP pressed on the keyboard</source>
        <translation>PARADA DE EMERGENCIA pulsada en el teclado</translation>
    </message>
    <message>
        <location filename="../words.py" line="48" />
        <source>E-STOP sent from a terminal</source>
        <translation>PARADA DE EMERGENCIA enviada desde un terminal</translation>
    </message>
    <message>
        <location filename="../words.py" line="49" />
        <source>the emergency-stop button was pressed</source>
        <translation>se pulsó la seta de emergencia</translation>
    </message>
    <message>
        <location filename="../words.py" line="50" />
        <source>the patient pressed the hand switch</source>
        <translation>el paciente pulsó el pulsador de mano</translation>
    </message>
    <message>
        <location filename="../words.py" line="51" />
        <source>STOP pressed</source>
        <translation>PARAR pulsado</translation>
    </message>
    <message>
        <location filename="../words.py" line="52" />
        <source>a motor drive failed</source>
        <translation>falló un accionamiento de motor</translation>
    </message>
    <message>
        <location filename="../words.py" line="53" />
        <source>the platform position is unknown</source>
        <translation>la posición de la plataforma es desconocida</translation>
    </message>
    <message>
        <location filename="../words.py" line="54" />
        <source>a position sensor gave an impossible reading</source>
        <translation>un sensor de posición dio una lectura imposible</translation>
    </message>
    <message>
        <location filename="../words.py" line="55" />
        <source>force sensor overloaded</source>
        <translation>sensor de fuerza sobrecargado</translation>
    </message>
    <message>
        <location filename="../words.py" line="56" />
        <source>the force sensor stopped answering</source>
        <translation>el sensor de fuerza dejó de responder</translation>
    </message>
    <message>
        <location filename="../words.py" line="57" />
        <source>the force sensor reading is invalid</source>
        <translation>la lectura del sensor de fuerza no es válida</translation>
    </message>
    <message>
        <location filename="../words.py" line="58" />
        <source>force above the patient's limit</source>
        <translation>fuerza por encima del límite del paciente</translation>
    </message>
    <message>
        <location filename="../words.py" line="59" />
        <source>the control computer fell behind</source>
        <translation>el ordenador de control se retrasó</translation>
    </message>
    <message>
        <location filename="../words.py" line="60" />
        <source>lost contact with the controlling screen</source>
        <translation>se perdió el contacto con la pantalla que controla</translation>
    </message>
    <message>
        <location filename="../words.py" line="61" />
        <source>inversion/eversion at the end of the patient's range</source>
        <translation>inversión/eversión al final del rango del paciente</translation>
    </message>
    <message>
        <location filename="../words.py" line="62" />
        <source>dorsi/plantarflexion at the end of the patient's range</source>
        <translation>dorsi/plantarflexión al final del rango del paciente</translation>
    </message>
    <message>
        <location filename="../words.py" line="63" />
        <source>inversion/eversion faster than the patient's limit</source>
        <translation>inversión/eversión más rápida que el límite del paciente</translation>
    </message>
    <message>
        <location filename="../words.py" line="64" />
        <source>dorsi/plantarflexion faster than the patient's limit</source>
        <translation>dorsi/plantarflexión más rápida que el límite del paciente</translation>
    </message>
    <message>
        <location filename="../words.py" line="78" />
        <source>actuator %1 at the end of its travel</source>
        <translation>actuador %1 al final de su recorrido</translation>
    </message>
    <message>
        <location filename="../words.py" line="79" />
        <source>actuator %1 near the end of its travel</source>
        <translation>actuador %1 cerca del final de su recorrido</translation>
    </message>
    <message>
        <location filename="../words.py" line="80" />
        <source>actuator %1 moving too fast</source>
        <translation>actuador %1 demasiado rápido</translation>
    </message>
    <message>
        <location filename="../words.py" line="81" />
        <source>actuator %1 accelerating too hard</source>
        <translation>actuador %1 acelera demasiado</translation>
    </message>
    <message>
        <location filename="../words.py" line="82" />
        <source>actuator %1 could not follow its path</source>
        <translation>actuador %1 no pudo seguir su trayectoria</translation>
    </message>
    <message>
        <location filename="../words.py" line="83" />
        <source>actuator %1 pushing too hard</source>
        <translation>actuador %1 empuja demasiado</translation>
    </message>
    <message>
        <location filename="../words.py" line="84" />
        <source>position sensor %1 stopped changing</source>
        <translation>el sensor de posición %1 dejó de cambiar</translation>
    </message>
    <message>
        <location filename="../pages/login.py" line="26" />
        <source>Log in to use the robot</source>
        <translation>Inicie sesión para usar el robot</translation>
    </message>
    <message>
        <location filename="../pages/login.py" line="42" />
        <source>User name</source>
        <translation>Usuario</translation>
    </message>
    <message>
        <location filename="../pages/login.py" line="43" />
        <source>Password</source>
        <translation>Contraseña</translation>
    </message>
    <message>
        <location filename="../pages/login.py" line="68" />
        <source>Enter your user name and password.</source>
        <translation>Escriba su usuario y contraseña.</translation>
    </message>
    <message>
        <location filename="../pages/login.py" line="71" />
        <source>Checking…</source>
        <translation>Comprobando…</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="35" />
        <source>%1: a number is needed</source>
        <extracomment>Clinical limit fields edited here: (key, label) — degrees from neutral, N, deg/s.</extracomment>
        <translation>%1: se necesita un número</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="54" />
        <source>Search by code</source>
        <translation>Buscar por código</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="60" />
        <source>automatic when empty</source>
        <translation>automático si se deja vacío</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="63" />
        <source>right</source>
        <translation>derecho</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="64" />
        <source>left</source>
        <translation>izquierdo</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="65" />
        <source>both</source>
        <translation>ambos</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="67" />
        <source>Register patient</source>
        <translation>Registrar paciente</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="69" />
        <source>New patient</source>
        <translation>Nuevo paciente</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="71" />
        <source>Code</source>
        <translation>Código</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="72" />
        <location filename="../pages/patients.py" line="197" />
        <source>Body mass (kg)</source>
        <translation>Masa corporal (kg)</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="73" />
        <source>Affected side</source>
        <translation>Lado afectado</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="74" />
        <source>Diagnosis (no names)</source>
        <translation>Diagnóstico (sin nombres)</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="82" />
        <location filename="../pages/patients.py" line="150" />
        <source>Choose a patient.</source>
        <translation>Elija un paciente.</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="88" />
        <source>Prescribe limits</source>
        <translation>Prescribir límites</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="95" />
        <source>Reason</source>
        <translation>Motivo</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="101" />
        <source>Save the new limits</source>
        <translation>Guardar los nuevos límites</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="106" />
        <source>Show identifying data (audited)</source>
        <translation>Mostrar datos identificativos (queda registrado)</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="111" />
        <source>Use for the session</source>
        <translation>Usar para la sesión</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="126" />
        <source>Sessions</source>
        <translation>Sesiones</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="221" />
        <source>Give the four ranges of motion.</source>
        <translation>Indique los cuatro rangos de movimiento.</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="276" />
        <source>Patient %1 registered.</source>
        <translation>Paciente %1 registrado.</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="280" />
        <source>Limits saved.</source>
        <translation>Límites guardados.</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="284" />
        <source>No identifying data recorded.</source>
        <translation>No hay datos identificativos registrados.</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="302" />
        <source>Patient %1</source>
        <translation>Paciente %1</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="303" />
        <source>Body mass: %1 kg</source>
        <translation>Masa corporal: %1 kg</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="304" />
        <source>Affected side: %1</source>
        <translation>Lado afectado: %1</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="305" />
        <source>Diagnosis: %1</source>
        <translation>Diagnóstico: %1</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="308" />
        <source>No limits prescribed yet: a session needs them.</source>
        <translation>Aún no hay límites prescritos: una sesión los necesita.</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="312" />
        <source>dorsiflexion</source>
        <translation>dorsiflexión</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="313" />
        <source>plantarflexion</source>
        <translation>plantarflexión</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="314" />
        <source>inversion</source>
        <translation>inversión</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="314" />
        <source>eversion</source>
        <translation>eversión</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="317" />
        <source>Limits in force: %1; force ≤ %2 N; speed ≤ %3 °/s — set by %4 on %5</source>
        <translation>Límites vigentes: %1; fuerza ≤ %2 N; velocidad ≤ %3 °/s — fijados por %4 el %5</translation>
    </message>
    <message>
        <location filename="../pages/patients.py" line="332" />
        <source>No sessions yet.</source>
        <translation>Aún no hay sesiones.</translation>
    </message>
</context>
</TS>