"""The actuator's sensors as physical parts, one module each: value-level digitising
(compiled), line-level model and fault knobs together.

* :mod:`~plant.sensors.motor_encoder`: RLS RMB30SI, SSI absolute + ABI incremental;
* :mod:`~plant.sensors.hall_sensor`: the motor's hall sensors;
* :mod:`~plant.sensors.piston_encoder`: Renishaw RESOLUTE, BiSS-C;
* :mod:`~plant.sensors.strain_gauge`: strain bridge + AD7195;
* :mod:`~plant.sensors.pressure_sensors`: five pressure sensors and the oil temperature
  sensor on the board's 8-channel ADC;
* :mod:`~plant.sensors.rod_temperature`: the connecting rod's temperature sensor (optional),
  on the same ADC;
* :mod:`~plant.sensors.current_sense`: the board's phase-current ADC;
* :mod:`~plant.sensors.readings`: noise and converter resolution of the plant's sensor
  outputs (``effects.sensor_noise``, ``effects.quantisation``), kept out of the physics.

:mod:`~plant.sensors.chips` holds their shared parameter array; :mod:`~plant.sensors.harness`
wires them to the driver board's inputs (value level and line level). The analog sensors are
rows of :data:`firmware_model.fpga.layout.ANALOG_INPUTS`; a part module says what each
measures in its ``ANALOG_SOURCES``.
"""
