"""The MCU board's STM32F4: the actuator force loop at 5 kHz in float32 (thesis 5.3, 6.3.1)."""
