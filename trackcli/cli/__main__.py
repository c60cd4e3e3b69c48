from trackcli.cli.main import main

main()
