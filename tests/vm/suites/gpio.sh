# GPIO: the PL061 of the virt machine is /dev/gpiochip0 (8 lines, built into the
# kernel). gpio-keys takes line 3 for the power button, so a busy line can be tested.
suite_targets=(test_gpio test_status_lines)
suite_modules=(gpio_keys)
suite_init='sleep 1'
suite_env=(FOVEA_TEST_GPIO_BUSY_LINE=3)
suite_may_skip=0
